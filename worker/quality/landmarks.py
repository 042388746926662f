"""Quality of one object-landmark label: smooth tracks, on the object, not frozen.

Each view's 2 landmarks are the worker's own choice, so nothing matches them across views; a
label is judged on its own: temporal smoothness (jumps against the object's motion as the
other labels show it, or against the label's own neighbouring steps), distance to the
object's projected silhouette where a mask is given (the object's pose is known for those
frames), and how much of the clip it stands still. Pixels x right, y down, one view.
"""

from __future__ import annotations

import cv2
import numpy as np

from worker.geometry.cameras import CameraModel
from worker.quality.metrics import (
    AssignmentQC,
    completeness,
    error_issues,
    error_summary,
    num,
    per_point_and_frame,
    static_fraction,
)
from worker.quality.motion import (
    TargetMotion,
    expected_shake,
    moved_with,
    others_motion,
    track_jitter,
)
from worker.quality.view_labels import ViewLabels, decided_of, decided_xy, observed_xy

# A landmark within this distance (px) of the silhouette counts as on it: masks are rasterised
# at pixel centres and a careful click lands within ~2 px.
SILHOUETTE_TOLERANCE_PX = 3.0
# A frame-to-frame step shorter than this (px) is never a jump: objects move smoothly, a
# relabelled or swapped landmark leaps.
JUMP_FLOOR_PX = 8.0
# The object counts as moving in a clip when the other labels' landmarks get this far (median
# over labels, px) from where they were first placed: ten careful clicks' noise.
OBJECT_MOVES_PX = 20.0
# The object's motion as the other labels show it.
ObjectMotion = TargetMotion
# A step is the object's own motion, not a jump, unless it exceeds this multiple of the step
# the other labels take in the same frame (views see the motion at different scales).
JUMP_OVER_OTHERS = 3.0
# ... times the scale at which this view sees the motion against the others (_view_scale),
# within these bounds: never stricter than the others' own motion, and a label that moves far
# more than all others is no witness of its own scale.
VIEW_SCALE = (1.0, 4.0)
# With nothing else to show the object's motion, a large step is a jump only when it differs
# from the steps beside it by more than this multiple of them (_own_jumps): a lift from rest
# grows and turns over frames, a moved or swapped landmark leaps in one.
JUMP_OVER_NEIGHBOURS = 1.0


def _check(label: ViewLabels, masks: dict[int, np.ndarray] | None,
           camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    xy = np.asarray(label.xy, dtype=np.float64)
    visible = np.asarray(label.visible, bool)
    if xy.ndim != 3 or xy.shape[2] != 2 or visible.shape != xy.shape[:2]:
        raise ValueError(f"labels {label.key!r}: xy must have shape (F, P, 2) and visible (F, P), "
                         f"got {xy.shape} and {visible.shape}")
    for frame, mask in (masks or {}).items():
        if np.shape(mask) != (camera.height, camera.width):
            raise ValueError(f"masks[{frame}] must have shape ({camera.height}, {camera.width}), "
                             f"got {np.shape(mask)}")
        if not 0 <= frame < xy.shape[0]:
            raise ValueError(f"masks: frame {frame} is not in 0..{xy.shape[0] - 1}")
    return xy, visible


def silhouette_distances(xy: np.ndarray, visible: np.ndarray,
                         masks: dict[int, np.ndarray]) -> np.ndarray:
    """(F, P) px from each visible landmark to the nearest silhouette pixel (0 inside), NaN in
    frames without a mask, for occluded landmarks or landmarks without a position."""
    out = np.full(visible.shape, np.nan)
    for frame, mask in masks.items():
        mask = np.asarray(mask, bool)
        if not mask.any():
            continue
        # Distance of every pixel to the nearest silhouette pixel.
        dist = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
        h, w = mask.shape
        for p in range(visible.shape[1]):
            if not visible[frame, p] or not np.isfinite(xy[frame, p]).all():
                continue
            col = int(np.clip(np.rint(xy[frame, p, 0]), 0, w - 1))
            row = int(np.clip(np.rint(xy[frame, p, 1]), 0, h - 1))
            out[frame, p] = float(dist[row, col])
    return out


def _own_jumps(vec: np.ndarray, step: np.ndarray) -> np.ndarray:
    """(F-1, P) bool: of the label's steps (vec (F-1, P, 2) px and their lengths step), those
    that are jumps with nothing else to show the object's motion.

    A step over the floor is a jump where it stands out from the steps beside it: it differs
    (as a vector) from their mean by more than JUMP_OVER_NEIGHBOURS times the larger of them
    and the floor (a landmark moved, swapped or wrong in one frame). A lift grows and turns
    from frame to frame, whether it starts from rest or fills the clip, so its steps, however
    large against the label's typical one, are no jumps. Steps the label does not show (NaN)
    are no neighbours; a step with none is not judged here."""
    big = np.nan_to_num(step) > JUMP_FLOOR_PX
    pad = np.full((1, *vec.shape[1:]), np.nan)
    before, after = np.concatenate([pad, vec[:-1]]), np.concatenate([vec[1:], pad])
    has_before, has_after = np.isfinite(before).all(-1), np.isfinite(after).all(-1)
    # With one step beside it (next to a hidden stretch or the clip's end), the step on the
    # other side may have been as large as this one: half the difference is what stands out.
    one = np.where(has_before[..., None], before, after)
    beside = np.where((has_before & has_after)[..., None], (before + after) / 2.0,
                      (one + vec) / 2.0)
    scale = np.maximum(np.maximum(np.nan_to_num(np.linalg.norm(before, axis=-1)),
                                  np.nan_to_num(np.linalg.norm(after, axis=-1))), JUMP_FLOOR_PX)
    apart = np.nan_to_num(np.linalg.norm(vec - beside, axis=-1))
    return big & (apart > JUMP_OVER_NEIGHBOURS * scale)


def _view_scale(step: np.ndarray, others: np.ndarray) -> float:
    """How much larger this view sees the object's motion than the other labels do: the
    median ratio of the label's steps (F-1, P) px to the others' (F-1,) px over the frames
    where the others' motion sets the jump allowance (above the floor), within VIEW_SCALE; 1
    where there are none. A camera near the object, or one that sees the lift across its
    image rather than along its axis, sees every step of it several times larger."""
    moving = np.isfinite(others) & (JUMP_OVER_OTHERS * np.nan_to_num(others) > JUMP_FLOOR_PX)
    ratio = step[moving] / others[moving, None]
    ratio = ratio[np.isfinite(ratio)]
    if ratio.size == 0:
        return 1.0
    return float(np.clip(np.median(ratio), *VIEW_SCALE))


def jumps(xy: np.ndarray, others_step: np.ndarray | None = None
          ) -> tuple[np.ndarray, float | None]:
    """(F-1, P) bool steps that are jumps, and the label's typical (median) step, px.

    others_step: optional (F-1,) px, the step the other labels of the object take in each
    frame (NaN where none shows it); where known, a step is a jump when it exceeds
    JUMP_OVER_OTHERS times that at the scale this view sees the motion at (_view_scale), and
    the floor. In every frame, a step that stands out from the label's own steps beside it
    is a jump too (_own_jumps): where the others' landmarks are hidden or only suggestions,
    the object's motion is unknown, not zero, and within a fast lift the others' steps leave
    room for a landmark wrong in one frame.
    """
    vec = np.diff(xy, axis=0)
    step = np.linalg.norm(vec, axis=-1)
    finite = step[np.isfinite(step)]
    if finite.size == 0:
        return np.zeros(step.shape, bool), None
    typical = float(np.median(finite))
    own = _own_jumps(vec, step)
    if others_step is None:
        return own, typical
    # The other views show when the object moves: a step is judged against that frame's
    # motion, not against the label's own typical step (which the object's motion inflates).
    others = np.asarray(others_step, float)
    allowed = np.maximum(JUMP_OVER_OTHERS * _view_scale(step, others) * np.nan_to_num(others),
                         JUMP_FLOOR_PX)
    against = (np.nan_to_num(step) > allowed[:, None]) & np.isfinite(others)[:, None]
    return against | own, typical


def object_motion(labels: list[ViewLabels]) -> dict[str, ObjectMotion | None]:
    """For each label, the object's motion as the other labels (other views or other workers)
    show it through their workers' own decisions where they show the landmarks
    (ViewLabels.decided: a pre-filled suggestion kept unchanged witnesses nothing, nor does a
    hidden landmark's stored position, which stays or runs straight while the object may
    lift); None with fewer than two other labels."""
    motion = others_motion({lab.key: observed_xy(lab) for lab in labels
                            if decided_of(lab).any() or not np.isfinite(lab.xy).any()})
    return {lab.key: motion.get(lab.key) for lab in labels}


def moved_with_object(xy: np.ndarray, motion: ObjectMotion, shown: np.ndarray | None = None
                      ) -> float | None:
    """How far the label's landmarks travel compared with the other labels' (1 = as far or
    farther), when the object clearly moves; None for an object that stays put or that the
    label's landmarks are hidden through (worker.quality.motion.moved_with; shown: (F, P)
    where the label shows them)."""
    return moved_with(xy, motion, OBJECT_MOVES_PX, shown)


def _mask_motion_ratio(xy: np.ndarray, masks: dict[int, np.ndarray]) -> float | None:
    """Mean landmark path length over the silhouette centroid's, on consecutive masked frames."""
    centroid = {}
    for frame, mask in masks.items():
        rows, cols = np.nonzero(mask)
        if cols.size:
            centroid[frame] = np.array([cols.mean(), rows.mean()])
    label_path = object_path = 0.0
    for frame in sorted(centroid):
        if frame + 1 in centroid:
            step = np.linalg.norm(xy[frame + 1] - xy[frame], axis=-1)
            if np.isfinite(step).all():
                label_path += float(step.mean())
                object_path += float(np.linalg.norm(centroid[frame + 1] - centroid[frame]))
    return num(label_path / object_path) if object_path > 1.0 else None


def _own_shake(xy: np.ndarray, motion: ObjectMotion | None) -> float | None:
    """The track's shake (px per frame^2) beyond what the object's own motion gives a track
    that follows a turning, accelerating object (motion.expected_shake), taken out in
    quadrature; without others to compare with, the track's whole shake."""
    shake, expected = track_jitter(xy), expected_shake(xy, motion)
    if shake is None or expected is None:
        return shake
    return num(np.sqrt(max(shake ** 2 - expected ** 2, 0.0)))


def _track_metrics(xy: np.ndarray, visible: np.ndarray, motion: ObjectMotion | None
                   ) -> tuple[np.ndarray, np.ndarray, dict[str, float | None]]:
    """The track as sent, on its own: its jumps (F-1, P) bool beyond what the object's motion
    explains, between frames that both show the landmark (visible (F, P); across a hidden
    stretch the track's positions are in-betweens of where it was last and next shown, and
    the object may have moved meanwhile), those steps (F-1, P) px (NaN elsewhere), and
    jump_fraction and max_step_ratio of them, and jitter_px and static_fraction of the track as
    sent."""
    shown = np.where(visible[..., None], xy, np.nan)
    jump, typical = jumps(shown, motion.step if motion is not None else None)
    step = np.linalg.norm(np.diff(shown, axis=0), axis=-1)
    steps = np.isfinite(step)
    return jump, step, {
        "jump_fraction": num(jump.sum() / steps.sum()) if steps.any() else None,
        "max_step_ratio": num(np.nanmax(step) / max(typical, 0.5))
        if typical is not None else None,
        "jitter_px": _own_shake(xy, motion),
        "static_fraction": static_fraction(xy),
    }


def _issues(dist: np.ndarray, jump: np.ndarray, step: np.ndarray) -> list[dict]:
    """Spans off the silhouette, and each jump of the track (its step, px)."""
    issues = [dict(i, about="silhouette")
              for i in error_issues(dist, SILHOUETTE_TOLERANCE_PX, min_frames=1)]
    for f, p in zip(*np.nonzero(jump), strict=True):
        issues.append({"point": int(p), "frames": [int(f), int(f) + 1],
                       "error_px": num(step[f, p], 1), "about": "jump"})
    return issues


def score_landmarks(camera: CameraModel, label: ViewLabels,
                    masks: dict[int, np.ndarray] | None = None,
                    motion: ObjectMotion | None = None) -> AssignmentQC:
    """Quality of one object-landmark label.

    Args:
        camera: the view (its width and height size the masks).
        label: ViewLabels with xy (F, 2, 2) px and visible (F, 2).
        masks: optional {frame: (H, W) bool} the object's projected silhouette under its known
            pose in that frame.
        motion: optional ObjectMotion, the object's motion as the other labels show it
            (object_motion): steps it explains are not jumps, and a label that stays still
            while it moves scores a low moved_with_object.

    The checks against the silhouette and against the object's motion read only the worker's
    own decisions (label.decided); jumps, shake and stillness read the track as sent.

    Returns:
        AssignmentQC whose metrics hold, against the silhouette (None without masks),
        median/mean/p90_error_px and outlier_fraction (share of judged landmarks farther than
        SILHOUETTE_TOLERANCE_PX), motion_ratio (landmark vs silhouette centroid motion); and
        always jump_fraction, max_step_ratio, jitter_px, static_fraction, completeness,
        visible_fraction and working_time_s. per_joint / per_frame: median silhouette distance.
    """
    xy, visible = _check(label, masks, camera)
    decided = decided_of(label)
    own_xy = decided_xy(label)
    masks = masks or {}
    dist = silhouette_distances(xy, visible & decided, masks)
    judged = np.isfinite(dist)
    metrics = error_summary(dist)
    metrics["outlier_fraction"] = num((dist[judged] > SILHOUETTE_TOLERANCE_PX).mean()) \
        if judged.any() else None
    metrics["motion_ratio"] = _mask_motion_ratio(own_xy, masks)
    sent = visible & np.isfinite(xy).all(axis=-1)
    metrics["moved_with_object"] = moved_with_object(own_xy, motion, sent) \
        if motion is not None else None
    jump, step, track = _track_metrics(xy, visible, motion)
    metrics.update(track)
    metrics["completeness"] = completeness(xy, visible)
    metrics["visible_fraction"] = num(visible.mean())
    metrics["working_time_s"] = num(label.working_time_s, 1)
    own = sent & decided
    metrics["decided_fraction"] = num(own.sum() / sent.sum()) if sent.any() else None
    per_joint, per_frame = per_point_and_frame(dist)
    return AssignmentQC(key=label.key, view=label.view, metrics=metrics, per_joint=per_joint,
                        per_frame=per_frame, issues=_issues(dist, jump, step),
                        # Suggestions alone leave nothing to wait for (decide.py).
                        provisional=not judged.any() and metrics["moved_with_object"] is None
                        and (own.any() or not sent.any()))


def score_object(cameras: list[CameraModel], labels: list[ViewLabels],
                 masks: dict[int, dict[int, np.ndarray]] | None = None) -> dict[str, AssignmentQC]:
    """Every landmark label of one object, each judged alone and against the object's motion as
    the other labels (other views, other workers) see it.

    Args:
        cameras: one CameraModel per view (labels refer to them by index).
        labels: ViewLabels with xy (F, 2, 2) px and visible (F, 2), any number per view.
        masks: optional {view: {frame: (H, W) bool}} silhouettes under a known pose.

    Returns:
        {key: AssignmentQC} as score_landmarks, with moved_with_object where the object moved.
    """
    motion = object_motion(labels)
    return {lab.key: score_landmarks(cameras[lab.view], lab, (masks or {}).get(lab.view),
                                     motion[lab.key])
            for lab in labels}
