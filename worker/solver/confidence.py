"""How far each solved object pose can be trusted, frame by frame, from its evidence.

Evidence of object o at frame f under its solved pose:
  landmark views  distinct views with a mapped landmark labelled visible that reprojects within
                  INLIER_PX (a gross label does not count as support);
  landmark px     median reprojection error of those landmarks;
  depth views     views whose depth confirms the posed surface (`surface.DepthSupport`);
  see-through     share of the posed visible surface the cameras see past (it is not there);
  grip            for a held object, the distance from the pose its grip on the hand predicts
                  (the agreement with the other frames, through the hand).
A frame at rest is trusted by the motion prior (an untouched object does not move) unless depth
sees through it there; a frame at rest next to one in motion is judged by its evidence. Any
other frame is flagged, with the reason, when the evidence cannot pin it down: no landmark and
at most one view of depth, the cameras seeing through it, landmarks far off, or a pose far from
the grip. confidence (0..1) is the weakest of the factors, each scaled
so that 1 is well supported and 0 is the flag's threshold twice over. World frame; mm; px.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.solver.objects import box_corners, corner_distance_mm, landmark_errors
from worker.solver.problem import Problem
from worker.solver.state import SolveState
from worker.solver.surface import DepthSupport, depth_support

INLIER_PX = 24.0  # three Cauchy scales of the robust landmark loss
THROUGH_FLAG = 0.25
LANDMARK_FLAG_PX = 10.0
GRIP_FLAG_MM = 10.0
# Views of evidence (landmark views + depth views) that make a pose fully supported.
FULL_EVIDENCE = 4


@dataclass
class ObjectConfidence:
    """confidence (O, F) in [0, 1]; flags: per object, per frame None or the reason the pose
    is not trusted; landmark_views, depth_views (O, F) int; through (O, F) share."""

    confidence: np.ndarray
    flags: list[list[str | None]]
    landmark_views: np.ndarray
    depth_views: np.ndarray
    through: np.ndarray


def _plural(count: int, word: str) -> str:
    return f"{count} {word}" + ("" if count == 1 else "s")


def object_confidence(problem: Problem, state: SolveState) -> ObjectConfidence:
    """Confidence and flags of every solved object pose (see the module's rules)."""
    count, frames = len(problem.objects), problem.num_frames
    out = ObjectConfidence(np.ones((count, frames)), [[None] * frames for _ in range(count)],
                           np.zeros((count, frames), np.int64),
                           np.zeros((count, frames), np.int64), np.zeros((count, frames)))
    every = np.arange(frames)
    for o, obj in enumerate(problem.objects):
        poses = state.object_poses[o]
        errors = landmark_errors(problem, o, state.tables[o], every, poses)
        lm_views, lm_px = _landmark_evidence(state, o, errors)
        support = DepthSupport(np.zeros((frames, 0), np.int64), np.zeros((frames, 0), np.int64))
        if problem.depth_images is not None:
            support = depth_support(problem.cameras, problem.depth_images,
                                    problem.object_samples[o], poses, every)
        depth_views, through = support.support_views(), support.through_fraction()
        motion = state.motion[o] if o < len(state.motion) else None
        grip_mm = np.full(frames, np.nan)
        if motion is not None:
            grip_mm = corner_distance_mm(box_corners(np.asarray(obj.vertices, np.float64)),
                                         poses, motion.prior)
        role = "grasped object" if motion is not None and motion.held.any() else "object"
        rest = np.zeros(frames, bool) if motion is None else np.asarray(motion.rest, bool)
        for f in range(frames):
            at_rest = bool(rest[f]) and not _next_to_motion(rest, f)
            out.confidence[o, f], out.flags[o][f] = judge(
                f"{role} {obj.name!r}", at_rest, int(lm_views[f]), float(lm_px[f]),
                int(depth_views[f]), float(through[f]), float(grip_mm[f]))
        out.landmark_views[o], out.depth_views[o], out.through[o] = lm_views, depth_views, through
    return out


def _next_to_motion(rest: np.ndarray, frame: int) -> bool:
    """Whether a frame at rest borders one that is not: where an object starts or stops moving,
    the split between rest and motion is uncertain by a frame (in a fast clip the object may
    already be centimetres away), so such a frame is judged by its evidence, not the prior."""
    return bool((frame > 0 and not rest[frame - 1])
                or (frame + 1 < len(rest) and not rest[frame + 1]))


def _landmark_evidence(state: SolveState, index: int, errors: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(F,) distinct views with an inlier landmark and (F,) median inlier error px (NaN)."""
    marks = state.tables[index]
    frames = errors.shape[0]
    if not len(marks.views):
        return np.zeros(frames, np.int64), np.full(frames, np.nan)
    inlier = np.isfinite(errors) & (errors < INLIER_PX)
    views = np.stack([inlier[:, marks.views == v].any(axis=1)
                      for v in np.unique(marks.views)], axis=1).sum(axis=1)
    px = np.full(frames, np.nan)
    some = inlier.any(axis=1)
    px[some] = np.nanmedian(np.where(inlier, errors, np.nan)[some], axis=1)
    return views, px


def judge(what: str, at_rest: bool, lm_views: int, lm_px: float, depth_views: int,
           through: float, grip_mm: float) -> tuple[float, str | None]:
    """(confidence in [0, 1], reason or None) of one pose from its evidence: `what` names the
    object in the reason; at_rest: the motion prior holds it at its initial pose; lm_views,
    lm_px (NaN: none), depth_views, through (share) and grip_mm (NaN: not held) as in the
    module's list."""
    c_through = 1.0 - min(through / (2 * THROUGH_FLAG), 1.0)
    seen_through = (f"{what}: depth sees through {through:.0%} of its surface"
                    + (" where it rests" if at_rest else ""))
    if at_rest:
        return c_through, seen_through if through > THROUGH_FLAG else None
    factors = [min((lm_views + depth_views) / FULL_EVIDENCE, 1.0), c_through]
    if np.isfinite(lm_px):
        factors.append(1.0 - min(max(lm_px - LANDMARK_FLAG_PX / 2, 0.0) / LANDMARK_FLAG_PX, 1.0))
    if np.isfinite(grip_mm):
        factors.append(1.0 - min(grip_mm / (2 * GRIP_FLAG_MM), 1.0))
    confidence = float(min(factors))
    if lm_views == 0 and depth_views <= 1:
        return confidence, (f"{what} seen by {_plural(depth_views, 'view')} in depth, "
                            "no landmark visible")
    if lm_views + depth_views < 2:
        return confidence, f"{what} seen by {_plural(lm_views + depth_views, 'view')} only"
    if through > THROUGH_FLAG:
        return confidence, seen_through
    if np.isfinite(lm_px) and lm_px > LANDMARK_FLAG_PX:
        return confidence, f"{what}: its landmarks reproject {lm_px:.0f} px off"
    if np.isfinite(grip_mm) and grip_mm > GRIP_FLAG_MM:
        return confidence, f"{what}: {grip_mm:.0f} mm from where the hand holds it"
    return confidence, None
