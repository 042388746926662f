"""Object poses over a sequence (default optimiser): at rest unless the evidence moves them.

An object rests at its initial pose until the hand has touched it and the evidence (its
landmarks, or depth that sees through it where it rested) puts it elsewhere. Then it is held:
it moves rigidly with the palm, so its pose in the palm's frame is one constant, the grip G,
taken where the hand held it still at rest (G = palm^-1 rest, averaged over those frames: the
initial pose is exact and the palm is good to about a degree, while an object's own landmarks
and depth can be biased by the fingers over it). Held frames start where the palm leaves that
stillness. Each is fitted to its landmarks and depth with a prior towards palm(f) G; the prior
is what carries a frame whose landmarks are all hidden. An object that never moves
keeps its initial pose in every frame, exactly. World frame, metres; pixels; residuals px, mm.
"""

from __future__ import annotations

import numpy as np
import torch

from worker.geometry.transforms import compose_poses, invert_pose
from worker.solver.depth import Matches
from worker.solver.energies import MM_PER_M, ObjectData, object_residuals
from worker.solver.init import PALM_JOINTS, initial_object_poses, kabsch
from worker.solver.jacobians import object_jacobian, rigid_point_derivatives
from worker.solver.lm import cauchy_weights, levenberg_marquardt
from worker.solver.problem import MappedLandmarks, Problem
from worker.solver.projection import pose_matrix, transform
from worker.solver.state import ObjectMotion, SolveState, hand_vertices_world
from worker.solver.surface import depth_support
from worker.solver.triangulate import reprojection_px

# A hand vertex this close to an object's resting surface (m) touches it; only a touched
# object can leave its rest (the fingers close a few mm short of the surface).
CONTACT_M = 0.02
# Landmarks whose median reprojection error at rest exceeds this (px) say it moved: the
# robust loss's scale, about twice the median error of 3-5 px labels; a frame needs
# DEPART_LANDMARKS seen for its median to count. Frames between the true start of the motion and
# this evidence are recovered by comparing rest and grip frame by frame (see solve_motion).
DEPART_PX = 8.0
DEPART_LANDMARKS = 3
DEPART_NOISE = 2.5
# ... or the cameras see through this share of its surface where it rested.
DEPART_THROUGH = 0.3
# A palm that moves the grasped object's box corners less than this from one frame to the
# next (mm) holds still (a solved palm jitters by 1-2 mm there).
STILL_MM = 3.0
# Consecutive frames that must agree before an object is taken as lifted.
DEPART_RUN = 3
# Weight of the grip prior per squared mm of mean box-corner distance: about the palm's pose
# error (1-2 mm at the object), so that two views of landmarks or depth outweigh it.
W_GRIP = 1.5


def box_corners(vertices: np.ndarray) -> np.ndarray:
    """(8, 3) corners of the axis-aligned box of vertices (N, 3), object frame."""
    lo, hi = vertices.min(0), vertices.max(0)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                     for z in (lo[2], hi[2])])


def corner_distance_mm(corners: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...,) mean distance, mm, of corners (K, 3) posed by a and b (..., 3, 4)."""
    pa = np.einsum("...ij,kj->...ki", a[..., :3], corners) + a[..., None, :, 3]
    pb = np.einsum("...ij,kj->...ki", b[..., :3], corners) + b[..., None, :, 3]
    return np.linalg.norm(pa - pb, axis=-1).mean(-1) * MM_PER_M


def palm_poses(problem: Problem, state: SolveState) -> np.ndarray:
    """(F, 3, 4) palm-to-world of the solved hand per frame (the mean hand's palm joints
    mapped onto the solved ones); unlabelled frames take the nearest labelled one; NaN
    everywhere without a hand."""
    frames = problem.num_frames
    out = np.full((frames, 3, 4), np.nan)
    hf = state.hand_frames
    if problem.subject is None or not len(hf):
        return out
    zero = torch.zeros(1, 51, dtype=torch.float64, device=problem.device)
    with torch.no_grad():
        rest = problem.subject.pose(zero)[0][0].cpu().numpy()[list(PALM_JOINTS)]
    joints = state.joints(problem)[:, list(PALM_JOINTS)]
    rot, trans = kabsch(np.repeat(rest[None], len(hf), 0), joints, np.ones(joints.shape[:2]))
    out[hf] = np.concatenate([rot, trans[..., None]], axis=-1)
    nearest = hf[np.abs(np.arange(frames)[:, None] - hf[None]).argmin(axis=1)]
    return out[nearest]


def touched(problem: Problem, state: SolveState, index: int) -> np.ndarray:
    """(F,) bool: the solved hand comes within CONTACT_M of object `index` at rest (True in
    every frame when there is no hand to say otherwise)."""
    frames = problem.num_frames
    if problem.subject is None:
        return np.ones(frames, bool)
    out = np.zeros(frames, bool)
    pose = problem.initial_poses[index]
    tree = problem.object_trees[index]
    lo, hi = tree.lo[0] - CONTACT_M, tree.hi[0] + CONTACT_M
    for f, verts in zip(state.hand_frames, _hand_vertices(problem, state), strict=True):
        local = (verts - pose[:, 3]) @ pose[:, :3]
        near = local[((local >= lo) & (local <= hi)).all(axis=1)]
        if len(near):
            out[f] = bool(tree.closest(near)[0].min() < CONTACT_M)
    return out


def _hand_vertices(problem: Problem, state: SolveState) -> np.ndarray:
    if not len(state.hand_frames):
        return np.zeros((0, 0, 3))
    return hand_vertices_world(problem, state.hand_pose[state.hand_frames])


def landmark_errors(problem: Problem, index: int, marks: MappedLandmarks, frames: np.ndarray,
                    poses: np.ndarray) -> np.ndarray:
    """(B, L) reprojection error px of the mapped landmarks at frames (B,) under poses
    (B, 3, 4); NaN where a landmark is not seen."""
    if not len(marks.views):
        return np.zeros((len(frames), 0))
    model = problem.object_vertices[index][marks.vertices]
    world = np.einsum("bij,lj->bli", poses[:, :, :3], model) + poses[:, None, :, 3]
    errors = np.stack([reprojection_px([problem.cameras[v]], world[:, k],
                                       marks.xy[frames, k][None])[0]
                       for k, v in enumerate(marks.views)], axis=1)
    return np.where(marks.gamma[frames], errors, np.nan)


def fit_poses(problem: Problem, index: int, marks: MappedLandmarks, frames: np.ndarray,
              start: np.ndarray, matches: list[Matches | None] | None,
              prior: np.ndarray | None, rounds: int) -> np.ndarray:
    """Poses (B, 3, 4) of object `index` at frames (B,) fitted from start (B, 3, 4) to its
    landmarks (Cauchy-reweighted each round), depth matches (per frame of the sequence) and,
    where prior (B, 3, 4) is finite, the grip prior."""
    settings = problem.settings
    poses = start.copy()
    corners = box_corners(np.asarray(problem.objects[index].vertices, np.float64))
    has_prior = None if prior is None else np.isfinite(prior).all(axis=(1, 2))
    model = problem.tensor(corners)
    for _ in range(rounds):
        robust = None
        if settings.robust and len(marks.views):
            robust = cauchy_weights(landmark_errors(problem, index, marks, frames, poses),
                                    settings.robust_scale_px)
        depth = None
        if matches is not None:
            depth = problem.depth_data(index, [matches[f] for f in frames],
                                       problem.object_faces[index],
                                       settings.depth_robust_mm if settings.robust else None)
        data = problem.object_data(index, frames, poses, marks, robust, depth)
        target = weight = None
        if prior is not None and has_prior is not None and has_prior.any():
            safe = np.where(has_prior[:, None, None], prior, poses)
            target = problem.tensor(np.einsum("bij,kj->bki", safe[:, :, :3], corners)
                                    + safe[:, None, :, 3])
            weight = problem.tensor(np.where(has_prior, np.sqrt(W_GRIP / len(corners)), 0.0))

        def residuals(d: torch.Tensor, data: ObjectData = data,
                      target: torch.Tensor | None = target,
                      weight: torch.Tensor | None = weight) -> torch.Tensor:
            out = object_residuals(d, data)
            if target is None or weight is None:
                return out
            rot, trans = pose_matrix(d, data.base)
            offset = (transform(rot, trans, model.expand(d.shape[0], -1, -1)) - target)
            return torch.cat((out, (offset * MM_PER_M * weight[:, None, None]).flatten(1)), 1)

        def jacobian(d: torch.Tensor, data: ObjectData = data,
                     weight: torch.Tensor | None = weight) -> torch.Tensor:
            out = object_jacobian(d, data)
            if weight is None:
                return out
            grip = rigid_point_derivatives(d, data.base, model) * MM_PER_M
            return torch.cat((out, (grip * weight[:, None, None, None]).flatten(1, 2)), 1)

        if data.vertex_ids.numel() == 0 and data.depth is None and target is None:
            return poses
        zero = torch.zeros(len(frames), 6, dtype=torch.float64, device=problem.device)
        delta, _ = levenberg_marquardt(residuals, zero, settings.lm_iterations,
                                       jacobian_fn=jacobian)
        rot, trans = pose_matrix(delta, data.base)
        poses = torch.cat((rot, trans[..., None]), -1).cpu().numpy()
    return poses


def departure(problem: Problem, index: int, marks: MappedLandmarks, touch: np.ndarray
              ) -> int | None:
    """The first frame at which object `index` has left its rest, or None: from the first
    touched frame on, the first of DEPART_RUN frames (fewer at the clip's end) in which its
    landmarks (DEPART_LANDMARKS or more seen) reproject DEPART_PX off at rest (median; or
    DEPART_NOISE times the median of the untouched frames, if larger), or the cameras see
    through its resting surface."""
    touched_at = np.flatnonzero(np.cumsum(touch) > 0)
    if not len(touched_at):
        return None
    frames = problem.num_frames
    rest = np.repeat(problem.initial_poses[index][None], len(touched_at), 0)
    moved = np.zeros(frames, bool)
    errors = landmark_errors(problem, index, marks, np.arange(frames),
                             np.repeat(problem.initial_poses[index][None], frames, 0))
    counted = np.isfinite(errors).sum(axis=1) >= DEPART_LANDMARKS
    median = np.full(frames, np.nan)
    median[counted] = np.nanmedian(errors[counted], axis=1)
    # Noisier labels scatter more at rest: the threshold grows with what the untouched frames
    # (surely at rest) show.
    untouched = median[:touched_at[0]]
    limit = DEPART_PX
    if np.isfinite(untouched).any():
        limit = max(DEPART_PX, DEPART_NOISE * float(np.nanmedian(untouched)))
    moved[touched_at] = median[touched_at] > limit
    if problem.depth_images is not None:
        support = depth_support(problem.cameras, problem.depth_images,
                                problem.object_samples[index], rest, touched_at)
        moved[touched_at] |= support.through_fraction() > DEPART_THROUGH
    for f in touched_at:
        run = moved[f:f + DEPART_RUN]
        if run[0] and run.all():
            return int(f)
    return None


def grip(palm: np.ndarray, poses: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(3, 4) object-in-palm pose: the weighted chordal mean of palm(f)^-1 pose(f) over frames
    where weight (B,) > 0; palm, poses (B, 3, 4)."""
    rel = compose_poses(invert_pose(palm), poses)
    w = weight / weight.sum()
    u, _, vt = np.linalg.svd(np.einsum("b,bij->ij", w, rel[:, :, :3]))
    rot = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
    return np.concatenate([rot, np.einsum("b,bi->i", w, rel[:, :, 3])[:, None]], axis=1)


def solve_motion(problem: Problem, state: SolveState, index: int,
                 palm: np.ndarray) -> ObjectMotion:
    """Decide where object `index` rests and where it is held; fit the grip and the held
    frames to their landmarks (writes state.object_poses[index]; depth comes later)."""
    frames = problem.num_frames
    marks = state.tables[index]
    initial = problem.initial_poses[index]
    rest = np.ones(frames, bool)
    state.object_poses[index] = initial
    touch = touched(problem, state, index)
    start = departure(problem, index, marks, touch)
    if start is None:
        return ObjectMotion(rest, ~rest, np.full((frames, 3, 4), np.nan))
    rest[start:] = False
    if not np.isfinite(palm[0]).all():
        # No hand to move with: each frame from its own landmarks and, later, depth.
        held = np.flatnonzero(~rest)
        starts = initial_object_poses(problem, index, marks)[held]
        state.object_poses[index, held] = fit_poses(problem, index, marks, held, starts, None,
                                                    None, 3)
        return ObjectMotion(rest, ~rest, np.full((frames, 3, 4), np.nan))
    # The hand closes on the resting object and holds still before lifting it: the grip is
    # the mean of palm(k)^-1 rest over those still frames (the palm's own frame-to-frame error
    # averages out); the frame before the departure if none is still.
    first = int(np.flatnonzero(np.cumsum(touch) > 0)[0])
    still = _still_frames(problem, index, palm, np.arange(max(first, 1), start), touch)
    if not len(still):
        still = np.array([max(start - 1, 0)])
    hold = grip(palm[still], np.repeat(initial[None], len(still), 0), np.ones(len(still)))
    # Once the palm has moved on from holding still, the object moves with it: rest and grip
    # agree while the palm is still, so the frames after the last still one are held.
    rest[still[-1] + 1:] = False
    held = np.flatnonzero(~rest)
    prior = np.full((frames, 3, 4), np.nan)
    prior[held] = compose_poses(palm[held], hold)
    state.object_poses[index, held] = fit_poses(problem, index, marks, held, prior[held], None,
                                                prior[held], 2)
    return ObjectMotion(rest, ~rest, prior, hold)


def _still_frames(problem: Problem, index: int, palm: np.ndarray, frames: np.ndarray,
                  touch: np.ndarray) -> np.ndarray:
    """The touched frames among frames (B,) where the palm moves object `index`, if it held
    it at rest, by less than STILL_MM from the frame before."""
    if not len(frames):
        return frames
    initial = problem.initial_poses[index]
    corners = box_corners(np.asarray(problem.objects[index].vertices, np.float64))
    in_palm = compose_poses(invert_pose(palm[frames]), initial)
    moved = corner_distance_mm(corners, compose_poses(palm[frames - 1], in_palm),
                               np.repeat(initial[None], len(frames), 0))
    return frames[touch[frames] & (moved < STILL_MM)]


def refit_held(problem: Problem, state: SolveState, index: int, motion: ObjectMotion,
               matches: list[Matches | None] | None, palm: np.ndarray) -> None:
    """Refit the held frames of object `index` with new depth matches, the grip prior moved
    with the palm as the hand's depth refit has moved it."""
    held = np.flatnonzero(motion.held)
    if not len(held):
        return
    marks = state.tables[index]
    prior = None
    if motion.grip is not None:
        motion.prior[held] = compose_poses(palm[held], motion.grip)
        prior = motion.prior[held]
    state.object_poses[index, held] = fit_poses(
        problem, index, marks, held, state.object_poses[index, held] if prior is None else prior,
        matches, prior, 2)
