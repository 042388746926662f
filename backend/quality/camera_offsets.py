"""Object landmarks after the solve, with each camera's systematic offset and lag taken out.

A camera whose calibration is off shows every solved object a few pixels away from where its
workers see it: the same map for every landmark of every object in that view. Per view it is
fitted (worker.quality.view_offset) to every landmark track of EVERY object target of the
sequence against its anchored point (worker.quality.anchored), so one worker's own errors do
not make the map of their view; where a view's map is trusted, the target's labels of that view
are taken back through it and anchored and judged again, and the report keeps the offset
(``camera_offset_px``) so the camera is named, not the worker. A camera out of step by a
whole frame (its sync) is found the same way, from every landmark track of its view against
the anchored points a frame on or back, and its labels judged against the scene as it shows
it (``camera_lag_frames``).
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


# A view is taken as out of step by a whole frame where its tracks sit less than half as far
# (in median) from the anchored points shifted by it as from them unshifted, on at least
# LAG_MIN_PAIRS judged positions where the object moves (LAG_MOTION_PX a frame either way).
# A careful track is 1-2 px from its point; a frame off puts it a frame's motion away.
LAG_GAIN = 0.5
LAG_MIN_PAIRS = 6
LAG_MOTION_PX = 2.0
LAGS = (-1, 1)


def _shifted(reprojection: np.ndarray, lag: int) -> np.ndarray:
    """(F, P, 2) px: the reprojection of frame f + lag at frame f (NaN beyond the clip)."""
    out = np.full_like(reprojection, np.nan)
    frames = len(reprojection)
    if lag >= 0:
        out[:frames - lag] = reprojection[lag:]
    else:
        out[-lag:] = reprojection[:frames + lag]
    return out


def _pairs(qc: AnchoredQC, label: ViewLabels, lag: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(anchored reprojection (N, 2), track (N, 2)) px where the label is judged, the
    reprojection taken ``lag`` frames on."""
    reprojection = _shifted(qc.reprojection, lag)
    judged = np.isfinite(qc.errors) & np.isfinite(reprojection).all(axis=-1)
    return reprojection[judged], np.asarray(label.xy, np.float64)[judged]


def view_tracks(session: Session, inputs: TargetInputs, scene: SolvedObjects,
                here: dict[str, AnchoredQC]) -> dict[int, list[tuple[AnchoredQC, ViewLabels]]]:
    """Per view, every landmark label of EVERY object target of the sequence with its anchored
    QC: ``here`` holds the target's own labels already anchored (by key); the other targets'
    labels are anchored here against ``scene`` (without depth: only where a track is judged
    matters)."""
    from worker.quality.anchored import score_anchored

    tracks: dict[int, list[tuple[AnchoredQC, ViewLabels]]] = {}
    for lab in inputs.labels:
        if lab.key in here:
            tracks.setdefault(lab.view, []).append((here[lab.key], lab))
    for key in _object_targets(session, inputs.sequence_id):
        if key == inputs.target_key:
            continue
        other = target_inputs(session, inputs.sequence_id, key)
        index = int(key.split(":", 1)[1])
        for lab in other.labels:
            tracks.setdefault(lab.view, []).append(
                (score_anchored(other.cameras[lab.view], lab, scene, index), lab))
    return tracks


def _gaps(found: list[tuple[AnchoredQC, ViewLabels]]) -> dict[int, np.ndarray]:
    """{lag: track-to-anchored-point distances (N,) px} over the judged positions where the
    anchored point moves by at least LAG_MOTION_PX a frame either way (a still object says
    nothing of timing), the same positions for every lag."""
    out: dict[int, list[np.ndarray]] = {lag: [] for lag in (0, *LAGS)}
    for qc, lab in found:
        xy = np.asarray(lab.xy, np.float64)
        shifted = {lag: _shifted(qc.reprojection, lag) for lag in out}
        moving = np.isfinite(qc.errors)
        for lag in LAGS:
            step = np.linalg.norm(shifted[lag] - qc.reprojection, axis=-1)
            moving &= np.nan_to_num(step, nan=0.0) >= LAG_MOTION_PX
        for lag, rep in shifted.items():
            out[lag].append(np.linalg.norm(rep[moving] - xy[moving], axis=-1))
    return {lag: np.concatenate(gaps) if gaps else np.empty(0) for lag, gaps in out.items()}


def landmark_lags(tracks: dict[int, list[tuple[AnchoredQC, ViewLabels]]]) -> dict[int, int]:
    """Per view, the whole frames its images are out of step with the solved objects (0, or
    -1 late / +1 early: a late camera's frame f shows the scene of f - 1), from every landmark
    track of the view at once, so one worker's own timing does not make the view's."""
    lags = {}
    for view, found in tracks.items():
        gaps = _gaps(found)
        lags[view] = 0
        if gaps[0].size < LAG_MIN_PAIRS:
            continue
        cost = {lag: float(np.median(gap)) for lag, gap in gaps.items()}
        best = min(LAGS, key=lambda lag: cost[lag])
        if cost[best] < LAG_GAIN * cost[0]:
            lags[view] = best
    return lags


def lagged(scene: SolvedObjects, lag: int) -> SolvedObjects:
    """The scene as a view ``lag`` frames out of step shows it (poses of frame f + lag at f,
    unknown beyond the clip)."""
    import dataclasses

    poses = np.full_like(scene.poses, np.nan)
    frames = scene.poses.shape[1]
    if lag >= 0:
        poses[:, :frames - lag] = scene.poses[:, lag:]
    else:
        poses[:, -lag:] = scene.poses[:, :frames + lag]
    return dataclasses.replace(scene, poses=poses)


def landmark_offsets(inputs: TargetInputs, tracks: dict[int, list[tuple[AnchoredQC, ViewLabels]]],
                     lags: dict[int, int]) -> dict[int, ViewOffset]:
    """Per view, the camera's map from the landmark tracks of every object target (each
    view's reprojections taken by its lag first)."""
    from worker.quality.view_offset import fit_view_offset

    return {view: fit_view_offset(view, [_pairs(qc, lab, lags.get(view, 0))
                                         for qc, lab in found],
                                  inputs.cameras[view].K[:2, 2])
            for view, found in tracks.items()}


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
