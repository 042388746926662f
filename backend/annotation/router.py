"""Annotation endpoints: admin task set-up, and the worker-facing page API.

Workers are identified only by a signed token (in the page URL, sent as a bearer header):
an assignment token opens exactly one assignment; a task token opens a read-only preview
and can be exchanged for an assignment token when the marketplace names the assignment; a
review token (made by an admin) shows one assignment's saved tracks and can change nothing.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, Query, Request
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend import pipeline
from backend.accounts.deps import CurrentAdmin, bearer_token
from backend.annotation import proposals, service, stretch_warnings, suggestions
from backend.annotation.models import Assignment, Task
from backend.annotation.points import point_colours, point_names, skeleton
from backend.annotation.schemas import (
    MAX_SAVE_BYTES,
    AnnotateTaskRead,
    AssignmentCreate,
    AssignmentLink,
    AssignmentRead,
    FramesLinks,
    HighlightUpdate,
    PreviewLink,
    ReadonlyLink,
    SaveResult,
    StartRequest,
    TaskRead,
    TokenRead,
    TracksPayload,
    TracksSave,
)
from backend.annotation.tokens import (
    ASSIGNMENT_SCOPE,
    PREVIEW_ASSIGNMENT_ID,
    REVIEW_SCOPE,
    REVIEW_TOKEN_TTL_S,
    TASK_SCOPE,
    assignment_token,
    frame_token,
    page_url,
    review_token,
    task_token,
)
from backend.config import get_settings
from backend.crowd import holds
from backend.db import SessionDep, session_scope
from backend.errors import Forbidden, Unauthorized
from backend.middleware import JSONBodyRoute, body_limit
from backend.progress.schemas import TaskState
from backend.progress.service import task_states
from backend.security import verify_token
from backend.storage import get_storage
from backend.validation import MAX_INT32, Id, Offset, QueryId

# Its JSON bodies (a track save is the most frequent request) are parsed by msgspec.
router = APIRouter(prefix="/api", tags=["annotation"], route_class=JSONBodyRoute)

# Both run on the event loop (no thread hop): they only check the token's signature.
async def _worker_claims(request: Request) -> dict[str, Any]:
    token = bearer_token(request)
    if token is None:
        raise Unauthorized("this page needs the token from its link (Authorization: Bearer)")
    return verify_token(token, get_settings().signing_key,
                        (ASSIGNMENT_SCOPE, TASK_SCOPE, REVIEW_SCOPE))


async def _writer_claims(claims: Annotated[dict[str, Any], Depends(_worker_claims)]
                   ) -> dict[str, Any]:
    """The claims of a token that may change labels (checked before the body is read)."""
    if claims["scope"] == REVIEW_SCOPE:
        raise Forbidden("a read-only review link cannot save or submit labels")
    return claims


WorkerClaims = Annotated[dict[str, Any], Depends(_worker_claims)]
WriterClaims = Annotated[dict[str, Any], Depends(_writer_claims)]


def _assignment_id(claims: dict[str, Any]) -> int:
    if claims["scope"] != ASSIGNMENT_SCOPE:
        raise Unauthorized("a preview link cannot change labels; accept the HIT first")
    return int(claims["assignment_id"])


def _assignment_of(session: SessionDep, claims: dict[str, Any]) -> Assignment:
    return service.get_assignment_or_raise(session, _assignment_id(claims))


def _task_reads(session: Session, tasks: list[Task]) -> list[TaskRead]:
    """The tasks as the API shows them, each with its state derived from its work."""
    states = task_states(session, [t.id for t in tasks])
    return [_task_read(t, states[t.id].state) for t in tasks]


def _task_read(task: Task, status: TaskState) -> TaskRead:
    return TaskRead(
        id=task.id, kind=task.kind, sequence_id=task.sequence_id, serial=task.camera.serial,
        target_key=task.target_key, num_points=task.num_points,
        num_frames=task.sequence.num_frames, width=task.camera.width, height=task.camera.height,
        fps=task.sequence.fps, point_names=point_names(task.kind),
        point_colors=point_colours(task.kind), skeleton=skeleton(task.kind),
        highlight=task.highlight, status=status,
    )


def _page_url(token: str, **params: str) -> str:
    return page_url(get_settings().public_url, token, **params)


# ----- admin -----------------------------------------------------------------------------

@router.post("/sequences/{sequence_id}/tasks", response_model=list[TaskRead])
def create_tasks(sequence_id: Id, session: SessionDep, _: CurrentAdmin) -> list[TaskRead]:
    """One task per view and target; running it again creates only what is missing."""
    tasks = service.create_tasks(session, get_storage(), sequence_id)
    return _task_reads(session, [service.get_task_or_raise(session, t.id) for t in tasks])


@router.get("/tasks", response_model=list[TaskRead])
def list_tasks(session: SessionDep, _: CurrentAdmin, sequence_id: QueryId = None,
               limit: int = Query(500, ge=1, le=5000),
               offset: Offset = 0) -> list[TaskRead]:
    """Tasks in id order, ``limit`` (500, at most 5,000) from ``offset`` on."""
    return _task_reads(session, service.list_tasks(session, sequence_id, limit, offset))


@router.put("/tasks/{task_id}/highlight", response_model=TaskRead)
def set_highlight(task_id: Id, body: HighlightUpdate, session: SessionDep,
                  _: CurrentAdmin) -> TaskRead:
    """Draw the object's box by hand (when its projected initial pose is missing or wrong)."""
    task = service.set_highlight_box(session, service.get_task_or_raise(session, task_id), body.box)
    return _task_reads(session, [task])[0]


@router.post("/tasks/{task_id}/assignments", response_model=AssignmentLink)
def create_assignment(task_id: Id, body: AssignmentCreate, session: SessionDep,
                      _: CurrentAdmin) -> AssignmentLink:
    """A direct assignment link for a named worker (outside any marketplace)."""
    task = service.get_task_or_raise(session, task_id)
    assignment = service.create_assignment(session, task, body.worker_id)
    token = assignment_token(task, assignment)
    url = _page_url(token, assignmentId=assignment.external_id, workerId=assignment.worker_id)
    return AssignmentLink(assignment_id=assignment.id, external_id=assignment.external_id,
                          token=token, page_url=url)


@router.post("/tasks/{task_id}/preview-token", response_model=PreviewLink)
def create_preview_token(task_id: Id, session: SessionDep, _: CurrentAdmin) -> PreviewLink:
    task = service.get_task_or_raise(session, task_id)
    token = task_token(task)
    return PreviewLink(token=token,
                       page_url=_page_url(token, assignmentId=PREVIEW_ASSIGNMENT_ID))


@router.post("/assignments/{assignment_id}/readonly-link", response_model=ReadonlyLink)
def create_readonly_link(assignment_id: Id, session: SessionDep,
                         _: CurrentAdmin) -> ReadonlyLink:
    """The annotation page showing the assignment's saved tracks read-only, with a "read-only
    review" banner: its token reads the task, the tracks and the frames, refuses every save
    and submit (403) and expires in an hour."""
    assignment = service.get_assignment_or_raise(session, assignment_id)
    task = service.get_task_or_raise(session, assignment.task_id)
    token = review_token(task, assignment)
    expires_at = datetime.now(UTC) + timedelta(seconds=REVIEW_TOKEN_TTL_S)
    url = page_url("", token, mode="review", assignmentId=assignment.external_id,
                   workerId=assignment.worker_id)
    return ReadonlyLink(url=url, expires_at=expires_at)


@router.get("/assignments/{assignment_id}/dense")
def dense_tracks(assignment_id: Id, session: SessionDep, _: CurrentAdmin) -> dict[str, Any]:
    """Every point of an assignment at every frame: x, y (image px, null where unplaced or
    occluded without a position), visible, and state (keyframe / interpolated / unplaced)."""
    from worker.tracks.interpolate import dense_track

    assignment = service.get_assignment_or_raise(session, assignment_id)
    task = service.get_task_or_raise(session, assignment.task_id)
    names = point_names(task.kind)
    points = []
    for track in assignment.tracks:
        dense = dense_track(track.keyframes, task.sequence.num_frames)
        xy = [[None if v != v else round(v, 4) for v in row] for row in dense.xy.tolist()]
        points.append({"point": track.point_index, "name": names[track.point_index],
                       "xy": xy, "visible": dense.visible.tolist(), "state": dense.state_names()})
    return {"assignment_id": assignment.id, "version": assignment.version,
            "num_frames": task.sequence.num_frames, "points": points}


# ----- worker-facing ---------------------------------------------------------------------

def _opened_before(task_id: int, body: StartRequest) -> bool:
    """Whether the assignment was opened here before (then for this task, worker and HIT);
    read in a unit of work of its own, closed before the marketplace is asked."""
    with session_scope() as session:
        service.get_task_or_raise(session, task_id)
        ours = session.scalars(select(Assignment).where(
            Assignment.external_id == body.assignment_id)).one_or_none()
        if ours is None:
            return False
        if (ours.task_id, ours.worker_id, ours.hit_id) != (task_id, body.worker_id,
                                                           body.hit_id):
            raise Forbidden(f"assignment {body.assignment_id} belongs to another task, worker "
                            "or HIT")
        return True


@router.post("/annotate/start", response_model=TokenRead)
def start(body: StartRequest, session: SessionDep) -> TokenRead:
    """Exchange a HIT's task token and the marketplace's ids for an assignment token.

    Only a marketplace assignment is started here, and only one the marketplace confirms
    (backend.crowd.holds): its HIT shows this task and a worker holds an assignment of it, or
    the marketplace's record of the assignment names that HIT and worker. A direct link
    (no HIT) is made by an admin only (POST /api/tasks/{id}/assignments). 403/404 say why an
    assignment is refused; 503 when the marketplace cannot be reached.
    """
    if body.assignment_id == PREVIEW_ASSIGNMENT_ID:
        raise Unauthorized("the HIT is not accepted yet (preview)")
    claims = verify_token(body.task_token, get_settings().signing_key, TASK_SCOPE)
    task_id = int(claims["task_id"])
    if not body.hit_id:
        raise Forbidden("no HIT id: an assignment starts here only from its marketplace HIT "
                        "(hitId, assignmentId and workerId in the page address); a direct "
                        "link is made by an admin (POST /api/tasks/{id}/assignments)")
    if not _opened_before(task_id, body):
        holds.confirm_held(task_id, body.hit_id, body.assignment_id, body.worker_id)
    task = service.get_task_or_raise(session, task_id)
    assignment = service.start_assignment(session, task, body.assignment_id, body.worker_id,
                                          body.hit_id)
    return TokenRead(token=assignment_token(task, assignment))


@router.get("/annotate/task", response_model=AnnotateTaskRead)
def read_task(claims: WorkerClaims, session: SessionDep) -> AnnotateTaskRead:
    task = service.get_task_or_raise(session, int(claims["task_id"]))
    # The frame links carry a read-only view token of their own, never the page's token.
    base = f"/api/sequences/{task.sequence_id}/views/{task.camera.serial}"
    token = frame_token(task)
    frames = FramesLinks(bundle_url=f"{base}/frames.bin?token={token}",
                         manifest_url=f"{base}/frames?token={token}")
    if claims["scope"] == TASK_SCOPE:
        return AnnotateTaskRead(mode="preview", task=_task_reads(session, [task])[0], frames=frames,
                                assignment=None)
    assignment = service.get_assignment_or_raise(session, int(claims["assignment_id"]))
    payload = service.tracks_payload(assignment)
    read = AssignmentRead(
        id=assignment.id, external_id=assignment.external_id, worker_id=assignment.worker_id,
        status=assignment.status, version=assignment.version, edit_count=assignment.edit_count,
        working_time_s=assignment.working_time_s,
        tracks=TracksPayload.model_validate(payload) if payload else None,
    )
    mode: Literal["edit", "submitted", "review"] = "review" if claims["scope"] == REVIEW_SCOPE \
        else "edit" if assignment.status == "working" else "submitted"
    return AnnotateTaskRead(mode=mode, task=_task_reads(session, [task])[0], frames=frames,
                            assignment=read)


@router.post("/annotate/proposals", response_model=proposals.ProposalsRead,
             openapi_extra=body_limit(MAX_SAVE_BYTES))
def tracking_proposals(body: proposals.ProposalsRequest, claims: WriterClaims,
                       session: SessionDep) -> proposals.ProposalsRead:
    """Positions between the keyframes sent, tracked in the view's frames (Lucas-Kanade from
    both keyframes of each span, stopped where a forward-backward check fails): per point and
    frame of the range, a position, whether it holds (ok) and its error. Nothing is stored;
    an accepted proposal is saved as a keyframe. 422 names bad keyframes or frame ranges."""
    return proposals.proposals(session, get_storage(), _assignment_of(session, claims), body)


@router.post("/annotate/stretches", response_model=stretch_warnings.StretchesRead,
             openapi_extra=body_limit(MAX_SAVE_BYTES))
def interpolation_check(body: proposals.ProposalsRequest, claims: WriterClaims,
                        session: SessionDep) -> stretch_warnings.StretchesRead:
    """The check the page shows before submit: stretches between the keyframes sent that the
    view's images say the track does not follow (tracked from both keyframes inwards), each
    with a sentence naming the point, the frames and the distance. Nothing is stored. 422
    names bad keyframes."""
    return stretch_warnings.stretch_warnings(session, get_storage(),
                                             _assignment_of(session, claims), body)


@router.get("/annotate/suggestions", response_model=suggestions.SuggestionsRead)
def prefill_suggestions(claims: WorkerClaims, session: SessionDep,
                        first_frame: int | None = Query(None, ge=0, le=MAX_INT32),
                        last_frame: int | None = Query(None, ge=0, le=MAX_INT32)
                        ) -> suggestions.SuggestionsRead:
    """Pre-fill suggestions for the assignment's view once its target has accepted work in 2
    other views: per point and frame (``first_frame``..``last_frame``, default the whole
    clip) a position triangulated from that work and a visibility from this view's depth,
    and per labelled view a fundamental matrix and its labels for epipolar lines. Nothing is
    stored; a review link may read them, a preview link may not (401). 422 names a frame
    outside the clip."""
    return suggestions.suggestions(session, get_storage(),
                                   suggestions.assignment_of(session, claims), first_frame,
                                   last_frame)


@router.put("/annotate/tracks", response_model=SaveResult,
            openapi_extra=body_limit(MAX_SAVE_BYTES))
def save_tracks(body: TracksSave, claims: WriterClaims, session: SessionDep) -> SaveResult:
    return SaveResult(version=service.autosave(session, _assignment_id(claims), body),
                      status="working")


@router.post("/annotate/submit", response_model=SaveResult,
             openapi_extra=body_limit(MAX_SAVE_BYTES))
def submit(body: TracksSave, claims: WriterClaims, session: SessionDep) -> SaveResult:
    assignment = pipeline.submit(session, _assignment_of(session, claims), body)
    return SaveResult(version=assignment.version, status=assignment.status)
