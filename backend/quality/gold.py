"""Training clips (gold): tasks with known labels that new workers label to qualify.

A clip's labels come from an accepted assignment or are given (e.g. a synthetic capture's
ground truth). A worker's labels of a clip are scored against them directly, in the image,
with the same metrics and decision rules as consensus scoring.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.models import Task, TrainingClip
from backend.annotation.service import get_assignment_or_raise, get_task_or_raise
from backend.errors import Conflict, DexlabelError, NotFound
from backend.labels import ACCEPTED
from backend.quality.schemas import TrainingClipCreate
from worker.tracks.readiness import completeness
from worker.tracks.validate import validate_keyframes

if TYPE_CHECKING:
    import numpy as np

    from worker.quality.metrics import AssignmentQC
    from worker.quality.view_labels import ViewLabels


class InvalidClip(DexlabelError, status_code=422, code="validation_error"):
    pass


def _check_tracks(task: Task, tracks: list[list[list[Any]]]) -> None:
    if len(tracks) != task.num_points:
        raise InvalidClip(f"a clip of a {task.kind} task needs {task.num_points} tracks, "
                          f"got {len(tracks)}", field="tracks")
    frames = task.sequence.num_frames
    for point, rows in enumerate(tracks):
        problems = validate_keyframes(rows, frames, task.camera.width, task.camera.height)
        if problems:
            raise InvalidClip(f"track {point}: {problems[0]}", field="tracks")
    report = completeness(tracks, frames)
    if not report["complete"]:
        raise InvalidClip("gold labels must cover every frame: " +
                          "; ".join(p["message"] for p in report["problems"][:5]),
                          field="tracks")


def create_clip(session: Session, body: TrainingClipCreate) -> TrainingClip:
    """Make a task a training clip, with labels from an assignment or given."""
    task = get_task_or_raise(session, body.task_id)
    if session.scalar(select(TrainingClip).where(TrainingClip.task_id == task.id)):
        raise Conflict(f"task {task.id} is already a training clip", state="training")
    if body.from_assignment_id is not None and body.tracks is None:
        source_assignment = get_assignment_or_raise(session, body.from_assignment_id)
        if source_assignment.task_id != task.id:
            raise InvalidClip(f"assignment {source_assignment.id} is of task "
                              f"{source_assignment.task_id}, not {task.id}",
                              field="from_assignment_id")
        if source_assignment.status != ACCEPTED:
            raise InvalidClip(f"assignment {source_assignment.id} is {source_assignment.status};"
                              " only approved labels can be gold", field="from_assignment_id")
        tracks = [t.keyframes for t in source_assignment.tracks]
        source = f"assignment:{source_assignment.id}"
    elif body.tracks is not None and body.from_assignment_id is None:
        tracks, source = body.tracks, "given"
    else:
        raise InvalidClip("give exactly one of from_assignment_id or tracks",
                          field="from_assignment_id")
    _check_tracks(task, tracks)
    clip = TrainingClip(task_id=task.id, source=source, tracks=tracks, note=body.note)
    session.add(clip)
    session.flush()
    return clip


def clip_of(session: Session, task_id: int) -> TrainingClip | None:
    return session.scalar(select(TrainingClip).where(TrainingClip.task_id == task_id))


def truth_tracks(session: Session, task_id: int, capture: Path) -> list[list[list[Any]]]:
    """Gold tracks of a task from a synthetic capture's ground truth (a keyframe per frame)."""
    import numpy as np

    from backend.captures.truth import CaptureTruth

    task = get_task_or_raise(session, task_id)
    if task.kind != "hand":
        raise InvalidClip("ground-truth gold exists for hand tasks only; use an approved "
                          "assignment for an object task", field="task_id")
    truth = CaptureTruth(capture)
    xy, visible = truth.points({"serial": task.camera.serial, "kind": "hand",
                                "num_frames": task.sequence.num_frames,
                                "target_key": task.target_key}, np.random.default_rng(0))
    w, h = task.camera.width, task.camera.height
    return [[[f, float(np.clip(xy[f, p, 0], 0, w - 1)), float(np.clip(xy[f, p, 1], 0, h - 1)),
              int(visible[f, p])] for f in range(xy.shape[0])] for p in range(xy.shape[1])]


def gold_dense(clip: TrainingClip, num_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The clip's gold as (F, P, 2) px and (F, P) visibility."""
    from worker.tracks.interpolate import dense_points

    return dense_points(enumerate(clip.tracks), num_frames, len(clip.tracks))


def score_training(session: Session, task_id: int, label: ViewLabels, num_frames: int
                   ) -> AssignmentQC:
    """A training assignment's quality against its clip's gold (worker.quality.gold)."""
    from worker.quality.gold import score_against_gold

    clip = clip_of(session, task_id)
    if clip is None:
        raise NotFound(f"task {task_id} is not a training clip")
    gold_xy, gold_visible = gold_dense(clip, num_frames)
    return score_against_gold(label, gold_xy, gold_visible)
