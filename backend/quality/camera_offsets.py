"""Object landmarks after the solve, with each camera's systematic offset taken out.

A camera whose calibration is off shows every solved object a few pixels away from where its
workers see it: the same map for every landmark of every object in that view. Per view it is
fitted (worker.quality.view_offset) to every landmark track of EVERY object target of the
sequence against its anchored point (worker.quality.anchored), so one worker's own errors do
not make the map of their view; where a view's map is trusted, the target's labels of that view
are taken back through it and anchored and judged again, and the report keeps the offset
(``camera_offset_px``) so the camera is named, not the worker.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.models import Task
from backend.quality.inputs import TargetInputs, target_inputs

if TYPE_CHECKING:
    from worker.quality.anchored import AnchoredQC
    from worker.quality.solved_scene import SolvedObjects
    from worker.quality.view_labels import ViewLabels
    from worker.quality.view_offset import ViewOffset


def _object_targets(session: Session, sequence_id: int) -> list[str]:
    return sorted(set(session.scalars(select(Task.target_key).where(
        Task.sequence_id == sequence_id, Task.kind == "object"))))


def _pairs(qc: AnchoredQC, label: ViewLabels) -> tuple[np.ndarray, np.ndarray]:
    """(anchored reprojection (N, 2), track (N, 2)) px where the label is judged."""
    judged = np.isfinite(qc.errors)
    return qc.reprojection[judged], np.asarray(label.xy, np.float64)[judged]


def landmark_offsets(session: Session, inputs: TargetInputs, scene: SolvedObjects,
                     here: dict[str, AnchoredQC]) -> dict[int, ViewOffset]:
    """Per view, the camera's map from the landmark tracks of every object target.

    ``here``: the target's own labels already anchored (by key); the other targets' labels
    are anchored here against ``scene`` (without depth: only where a track is judged matters).
    """
    from worker.quality.anchored import score_anchored
    from worker.quality.view_offset import fit_view_offset

    pairs: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    for lab in inputs.labels:
        if lab.key in here:
            pairs.setdefault(lab.view, []).append(_pairs(here[lab.key], lab))
    for key in _object_targets(session, inputs.sequence_id):
        if key == inputs.target_key:
            continue
        other = target_inputs(session, inputs.sequence_id, key)
        index = int(key.split(":", 1)[1])
        for lab in other.labels:
            qc = score_anchored(other.cameras[lab.view], lab, scene, index)
            pairs.setdefault(lab.view, []).append(_pairs(qc, lab))
    return {view: fit_view_offset(view, found, inputs.cameras[view].K[:2, 2])
            for view, found in pairs.items()}


def rescored(inputs: TargetInputs, label: ViewLabels, offset: ViewOffset, scene: SolvedObjects,
             target: int, depth: Any) -> AnchoredQC:
    """The label taken back through its camera's map, anchored and judged again; its replay
    drawn in the view's own pixels and the offset in its metrics."""
    from worker.quality.anchored import score_anchored
    from worker.quality.metrics import num
    from worker.quality.view_labels import ViewLabels

    moved = ViewLabels(label.key, label.view, offset.correct(label.xy), label.visible,
                       label.working_time_s, label.decided)
    qc = score_anchored(inputs.cameras[label.view], moved, scene, target, depth,
                        offset.forward)
    qc.reprojection = offset.forward(qc.reprojection)
    qc.metrics["camera_offset_px"] = num(offset.offset_px, 2)
    return qc


def camera_notes(inputs: TargetInputs, metrics: dict[str, Any], view: int) -> list[str]:
    """The report's words for a camera offset or lag taken out of a label's view (none
    without)."""
    serial = inputs.camera_rows[view].serial
    notes = []
    offset, lag = metrics.get("camera_offset_px"), metrics.get("camera_lag_frames")
    if offset is not None:
        notes.append(f"camera {serial}: the whole view is {offset:.1f} px off the other views "
                     "(its calibration); taken out before scoring, not charged to the worker")
    if lag:
        notes.append(f"camera {serial}: its frames show the scene {abs(lag):.0f} frame(s) "
                     f"{'late' if lag < 0 else 'early'} (its sync); taken out before scoring, "
                     "not charged to the worker")
    return notes
