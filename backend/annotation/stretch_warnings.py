"""The page's check before submit: interpolated stretches the view's images say the track
does not follow (worker.assist.stretches), as sentences the worker can act on.

The page sends the keyframes it holds (the form it saves); each stretch between two visible
keyframes is tracked in the view's own frames from both keyframes inwards, and one whose
tracked point leaves the straight line by more than the tolerance comes back as a warning
("ring tip moves 14 px between frames 4 and 8 that the track does not follow"). Nothing is
stored; QC makes the same check on the submitted work (worker.quality.stretch_qc).
"""

from __future__ import annotations

from pydantic import BaseModel
from sqlalchemy.orm import Session

from backend.annotation import service
from backend.annotation.models import Assignment
from backend.annotation.points import point_names
from backend.annotation.proposals import ProposalsRequest, grey_frames
from backend.annotation.schemas import TracksSave
from backend.storage import Storage
from worker.assist.lk import tracked_spans
from worker.assist.stretches import STRETCH_TOLERANCE_PX, check_stretches

# Clip frames read for one check at most (as the tracking proposals): longer clips are checked
# over their first frames only, and the answer says so.
MAX_CHECK_FRAMES = 300


class StretchWarning(BaseModel):
    """One stretch: its point, its keyframes [first, last], the frame where the tracked
    point is farthest from the line and that distance (image px), and the sentence."""

    point: int
    frames: list[int]
    frame: int
    offset_px: float
    message: str


class StretchesRead(BaseModel):
    """The warnings, worst first; tolerance_px: how far a stretch may leave the line;
    checked_frames: clip frames 0..checked_frames-1 were looked at."""

    tolerance_px: float
    checked_frames: int
    warnings: list[StretchWarning]


def stretch_warnings(session: Session, storage: Storage, assignment: Assignment,
                     body: ProposalsRequest) -> StretchesRead:
    """The warnings of the keyframes in ``body`` in the assignment's view (its frame range is
    ignored: the whole clip is checked). Raises InvalidTracks (422) for keyframes the page
    could not save."""
    task = service.get_task_or_raise(session, assignment.task_id)
    rows = service.check_tracks(service.clip_of(session, task.id),
                                TracksSave(version=0, tracks=body.tracks))
    count = min(task.sequence.num_frames, MAX_CHECK_FRAMES)
    names = point_names(task.kind)
    warnings: list[StretchWarning] = []
    if tracked_spans(rows, 0, count):
        frames = grey_frames(session, storage, task.camera_id, 0, count - 1,
                             (task.camera.width, task.camera.height))
        for issue in check_stretches(frames, rows).issues:
            name = names[issue.point].replace("_", " ") if issue.point < len(names) \
                else f"point {issue.point}"
            warnings.append(StretchWarning(
                point=issue.point, frames=[issue.first, issue.last], frame=issue.frame,
                offset_px=round(issue.offset_px, 1), message=issue.sentence(name)))
    return StretchesRead(tolerance_px=STRETCH_TOLERANCE_PX, checked_frames=count,
                         warnings=warnings)
