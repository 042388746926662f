"""What an admin reviews: one assignment's replay, and the queue of work waiting for an admin.

The replay shows a worker's tracks over the view's frames beside what they are judged against:
for a hand, where the other views place each joint without this label (the leave-one-out
consensus); for an object after a solve, where each anchored landmark reprojects. Both come
from the report (``QCReport.replay``, written by backend.quality.service.score_target); the
track is read from the stored keyframes as QC reads it (backend.quality.inputs.view_labels).

The queue is every report nobody has acted on whose assignment is still only submitted: the
work QC left for review, or could not decide yet (provisional), and, with automatic actions
off, every report. Worst first: clear verdicts (reject, then review) before provisional ones,
then the larger error first.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Query
from sqlalchemy import select
from sqlalchemy.orm import Session, defer, joinedload

from backend.accounts.deps import VIEW_SCOPE, CurrentAdmin
from backend.annotation.models import Assignment, Task
from backend.annotation.points import point_colours, point_names, skeleton
from backend.captures.models import Sequence
from backend.config import get_settings
from backend.db import SessionDep
from backend.errors import NotFound
from backend.quality.models import QCReport
from backend.quality.schemas import QueueItem, QueueRead, ReviewFrames, ReviewRead
from backend.quality.service import px_lists
from backend.security import sign_token
from backend.validation import Id, Offset
from worker.tracks.interpolate import dense_points

router = APIRouter()

# The replay's frame links carry a view token this long (seconds): a working day.
FRAME_TOKEN_TTL_S = 12 * 3600
# Order of outcomes in the queue: what QC judged worst first.
OUTCOME_RANK = {"reject": 0, "review": 1, "approve": 2}
# The error a queue row is ranked and shown by, px: the first of these the report has.
ERROR_METRICS = ("raw_median_error_px", "anchored_median_px", "median_error_px")

UNAVAILABLE = {
    None: "this report was scored before the replay was stored; score the target again "
          "(POST /api/qc/runs) to see the reference",
    "none": "no reference to compare with: object landmarks get one (the solved object's "
            "landmark) when the target is scored after a solve; this report was scored "
            "without one",
    "gold": "a training clip: the worker is judged against its known labels, not the views",
}


def _any_point(reference: list[Any]) -> bool:
    """Whether a stored (F, P, 2) reference places any point."""
    return any(p is not None and p[0] is not None for frame in reference for p in frame)


def _track(assignment: Assignment, num_frames: int, num_points: int) -> dict[str, Any]:
    """The worker's dense track: xy (F, P, 2) px (None = no position), visible (F, P) 0/1,
    and the keyframes (frame indices) the worker set per point."""
    tracks = sorted(assignment.tracks, key=lambda t: t.point_index)
    xy, visible = dense_points(((t.point_index, t.keyframes) for t in tracks), num_frames,
                               num_points)
    keyframes: list[list[int]] = [[] for _ in range(num_points)]
    for t in tracks:
        if 0 <= t.point_index < num_points:
            keyframes[t.point_index] = sorted({int(row[0]) for row in t.keyframes})
    return {"xy": px_lists(xy), "visible": visible.astype(int).tolist(), "keyframes": keyframes}


def _frames(sequence_id: int, serial: str, num_frames: int) -> ReviewFrames:
    """Links to the view's colour frames an <img> can load: each carries a view token (the
    admin's bearer header cannot travel with an image request)."""
    token = sign_token({"scope": VIEW_SCOPE, "sequence_id": sequence_id, "serial": serial},
                       get_settings().signing_key, FRAME_TOKEN_TTL_S)
    base = f"/api/sequences/{sequence_id}/views/{serial}"
    return ReviewFrames(
        token=token, expires_in=FRAME_TOKEN_TTL_S,
        urls=[f"{base}/frames/{i}.jpg?token={token}" for i in range(num_frames)],
        bundle_url=f"{base}/frames.bin?token={token}")


def review_of(session: Session, assignment_id: int) -> ReviewRead:
    report = session.scalar(select(QCReport).where(QCReport.assignment_id == assignment_id))
    if report is None:
        raise NotFound(f"assignment {assignment_id} has no QC report yet")
    assignment = session.get_one(Assignment, assignment_id)
    task = session.get_one(Task, report.task_id)
    sequence = session.get_one(Sequence, report.sequence_id)
    camera = task.camera
    frames, points = sequence.num_frames, task.num_points
    replay = report.replay or {}
    source = "gold" if report.method == "gold" else replay.get("source")
    reference = replay.get("reference") if source in ("consensus", "anchored") else None
    note = None if reference is not None else UNAVAILABLE.get(source, UNAVAILABLE[None])
    if reference is not None and not _any_point(reference):
        note = (f"no point of this view is fixed by two other views ({report.views} view(s) "
                "labelled so far): judge the track by the frames")
    return ReviewRead(
        assignment_id=assignment_id, task_id=task.id, sequence_id=sequence.id,
        sequence=f"{sequence.subject.name}/{sequence.name}", serial=camera.serial,
        kind=task.kind, target_key=task.target_key, worker_id=report.worker_id,
        assignment_status=assignment.status, num_frames=frames, width=camera.width,
        height=camera.height, point_names=point_names(task.kind)[:points],
        point_colours=point_colours(task.kind)[:points], skeleton=skeleton(task.kind),
        track=_track(assignment, frames, points),
        reference_source=source if reference is not None else None,
        reference=reference, errors=replay.get("errors") if reference is not None else None,
        reference_shown=replay.get("shown") if reference is not None else None,
        reference_note=note,
        swaps=report.swaps, issues=replay.get("issues", []), reasons=report.reasons,
        feedback=report.feedback, outcome=report.outcome, provisional=report.provisional,
        views=report.views, method=report.method, metrics=report.metrics,
        thresholds=report.thresholds, per_joint=report.per_joint, per_frame=report.per_frame,
        action=report.action, action_detail=report.action_detail,
        highlight=task.highlight, frames=_frames(sequence.id, camera.serial, frames))


def error_of(metrics: dict[str, Any]) -> float | None:
    """The px error a queue row is ranked and shown by (None when the report has none)."""
    for name in ERROR_METRICS:
        value = metrics.get(name)
        if value is not None:
            return float(value)
    return None


def _rank(row: QueueItem) -> tuple[int, int, float, int]:
    return (int(row.provisional), OUTCOME_RANK.get(row.outcome, 3),
            -(row.error_px if row.error_px is not None else -1.0), row.assignment_id)


def review_queue(session: Session, limit: int, offset: int) -> QueueRead:
    """Every report waiting for an admin, worst first; ``limit`` of them from ``offset``."""
    # Every waiting report is ranked, but only the page's replays (tens of kB each) are read,
    # for their issue counts.
    stmt = (select(QCReport, Sequence)
            .join(Assignment, Assignment.id == QCReport.assignment_id)
            .join(Sequence, Sequence.id == QCReport.sequence_id)
            .where(QCReport.action.is_(None), Assignment.status == "submitted")
            .options(defer(QCReport.replay), joinedload(Sequence.subject)))
    rows = []
    for report, sequence in session.execute(stmt):
        rows.append(QueueItem(
            assignment_id=report.assignment_id, sequence_id=report.sequence_id,
            sequence=f"{sequence.subject.name}/{sequence.name}", target_key=report.target_key,
            worker_id=report.worker_id, method=report.method, outcome=report.outcome,
            provisional=report.provisional, views=report.views,
            error_px=error_of(report.metrics), swaps=len(report.swaps), issues=0,
            reasons=report.reasons, action_detail=report.action_detail,
            updated_at=report.updated_at))
    rows.sort(key=_rank)
    page = rows[offset:offset + limit]
    replays: dict[int, dict[str, Any] | None] = dict(session.execute(
        select(QCReport.assignment_id, QCReport.replay)
        .where(QCReport.assignment_id.in_([row.assignment_id for row in page]))).all())
    for row in page:
        row.issues = len((replays.get(row.assignment_id) or {}).get("issues", []))
    return QueueRead(total=len(rows), offset=offset, limit=limit, items=page)


@router.get("/reports/{assignment_id}/review", response_model=ReviewRead)
def read_review(assignment_id: Id, session: SessionDep, _: CurrentAdmin) -> ReviewRead:
    """What the review page replays: the worker's track over the view's frames, the
    reference it is judged against and the error at every frame and point."""
    return review_of(session, assignment_id)


@router.get("/queue", response_model=QueueRead)
def read_queue(session: SessionDep, _: CurrentAdmin, limit: int = Query(50, ge=1, le=500),
               offset: Offset = 0) -> QueueRead:
    """Reports waiting for an admin across sequences, worst first: rejects, then reviews,
    then provisional verdicts, the larger error first within each."""
    return review_queue(session, limit, offset)
