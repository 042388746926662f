"""Annotation endpoints: admin task set-up, and the worker-facing page API.

Workers are identified only by a signed token (in the page URL, sent as a bearer header):
an assignment token opens exactly one assignment; a task token opens a read-only preview
and can be exchanged for an assignment token when the marketplace names the assignment; a
review token (made by an admin) shows one assignment's saved tracks and can change nothing.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any

from fastapi import APIRouter

from backend.accounts.deps import CurrentAdmin
from backend.annotation import proposals, service, stretch_warnings
from backend.annotation.deps import WriterClaims, assignment_id_of, assignment_of
from backend.annotation.points import point_names
from backend.annotation.schemas import (
    MAX_SAVE_BYTES,
    AssignmentCreate,
    AssignmentLink,
    PreviewLink,
    ReadonlyLink,
    SaveResult,
    TracksSave,
)
from backend.annotation.tokens import (
    PREVIEW_ASSIGNMENT_ID,
    READONLY_TOKEN_TTL_S,
    assignment_token,
    page_url,
    readonly_token,
    task_token,
)
from backend.config import get_settings
from backend.db import SessionDep
from backend.middleware import JSONBodyRoute, body_limit
from backend.storage import get_storage
from backend.validation import Id

# Its JSON bodies (a track save is the most frequent request) are parsed by msgspec.
router = APIRouter(prefix="/api", tags=["annotation"], route_class=JSONBodyRoute)

def _page_url(token: str, **params: str) -> str:
    return page_url(get_settings().public_url, token, **params)


# ----- admin -----------------------------------------------------------------------------

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
    token = readonly_token(task, assignment)
    expires_at = datetime.now(UTC) + timedelta(seconds=READONLY_TOKEN_TTL_S)
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

@router.post("/annotate/proposals", response_model=proposals.ProposalsRead,
             openapi_extra=body_limit(MAX_SAVE_BYTES))
def tracking_proposals(body: proposals.ProposalsRequest, claims: WriterClaims,
                       session: SessionDep) -> proposals.ProposalsRead:
    """Positions between the keyframes sent, tracked in the view's frames (Lucas-Kanade from
    both keyframes of each span, stopped where a forward-backward check fails): per point and
    frame of the range, a position, whether it holds (ok) and its error. Nothing is stored;
    an accepted proposal is saved as a keyframe. 422 names bad keyframes or frame ranges."""
    return proposals.proposals(session, get_storage(), assignment_of(session, claims), body)


@router.post("/annotate/stretches", response_model=stretch_warnings.StretchesRead,
             openapi_extra=body_limit(MAX_SAVE_BYTES))
def interpolation_check(body: proposals.ProposalsRequest, claims: WriterClaims,
                        session: SessionDep) -> stretch_warnings.StretchesRead:
    """The check the page shows before submit: stretches between the keyframes sent that the
    view's images say the track does not follow (tracked from both keyframes inwards), each
    with a sentence naming the point, the frames and the distance. Nothing is stored. 422
    names bad keyframes."""
    return stretch_warnings.stretch_warnings(session, get_storage(),
                                             assignment_of(session, claims), body)


@router.put("/annotate/tracks", response_model=SaveResult,
            openapi_extra=body_limit(MAX_SAVE_BYTES))
def save_tracks(body: TracksSave, claims: WriterClaims, session: SessionDep) -> SaveResult:
    return SaveResult(version=service.autosave(session, assignment_id_of(claims), body),
                      status="working")


