"""The default optimiser: all frames at once, Levenberg-Marquardt from triangulation.

Frames do not wait for each other: the hand starts from its triangulated joints in every frame
and objects from their landmarks, then every frame is refined in one batch. Keypoint residuals
are reweighted with a Cauchy loss (iteratively reweighted least squares) so that gross
labelling errors lose their pull; depth matches are renewed a few times (ICP-style rounds);
an optional smoothness term pulls each frame's joints towards its neighbours' mean.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from worker.solver.energies import (
    DepthData,
    HandData,
    ObjectData,
    hand_residuals,
    object_residuals,
)
from worker.solver.init import initial_hand, initial_object_poses
from worker.solver.jacobians import hand_jacobian
from worker.solver.lm import levenberg_marquardt
from worker.solver.mapping import map_landmarks, mapped_table
from worker.solver.problem import MappedLandmarks, Problem
from worker.solver.projection import pose_matrix
from worker.solver.state import SolveState

ROBUST_ROUNDS = 3


def cauchy_weights(errors: np.ndarray, scale: float) -> np.ndarray:
    """IRLS weights 1 / (1 + (e / scale)^2) of the Cauchy loss for errors (...) px."""
    return 1.0 / (1.0 + (np.nan_to_num(errors) / scale) ** 2)


def fit_hand(problem: Problem, state: SolveState, depth: DepthData | None, iterations: int,
             rounds: int, smooth: bool = False) -> None:
    """Refine state.hand_pose on the labelled frames in place."""
    subject = problem.require_subject()
    frames = state.hand_frames
    settings = problem.settings
    for _ in range(rounds):
        robust = None
        if settings.robust:
            robust = cauchy_weights(np.moveaxis(state.hand_errors(problem), 0, 1),
                                    settings.robust_scale_px)
        data = problem.hand_data(frames, robust, depth)
        if smooth and settings.w_smooth > 0:
            data.smooth_target = problem.tensor(_neighbour_mean(state.joints(problem), frames))
            data.sqrt_smooth = float(np.sqrt(settings.w_smooth))

        def residuals(p: torch.Tensor, data: HandData = data) -> torch.Tensor:
            return hand_residuals(subject, problem.rig, p, data)

        def jacobian(p: torch.Tensor, data: HandData = data) -> torch.Tensor:
            return hand_jacobian(subject, problem.rig, p, data)

        pose, _ = levenberg_marquardt(residuals, problem.tensor(state.hand_pose[frames]),
                                      iterations, jacobian_fn=jacobian)
        state.hand_pose[frames] = pose.cpu().numpy()


def _neighbour_mean(joints: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """(B, 21, 3) mean of each labelled frame's labelled neighbours' joints (itself if none)."""
    index = {int(f): b for b, f in enumerate(frames)}
    out = joints.copy()
    for b, f in enumerate(frames):
        near = [index[g] for g in (f - 1, f + 1) if g in index]
        if near:
            out[b] = joints[near].mean(axis=0)
    return out


def fit_object(problem: Problem, state: SolveState, index: int, marks: MappedLandmarks,
               depth: DepthData | None, iterations: int, rounds: int) -> None:
    """Refine state.object_poses[index] over all frames in place."""
    settings = problem.settings
    frames = np.arange(problem.num_frames)
    for _ in range(rounds):
        robust = None
        if settings.robust and len(marks.views):
            robust = cauchy_weights(state.landmark_errors(problem, index, marks),
                                    settings.robust_scale_px)
        base = state.object_poses[index]
        data = problem.object_data(index, frames, base, marks, robust, depth)
        if data.vertex_ids.numel() == 0 and data.depth is None:
            return

        def residuals(d: torch.Tensor, data: ObjectData = data) -> torch.Tensor:
            return object_residuals(d, data)

        zero = torch.zeros(len(frames), 6, dtype=torch.float64, device=problem.device)
        delta, _ = levenberg_marquardt(residuals, zero, iterations)
        rot, trans = pose_matrix(delta, data.base)
        state.object_poses[index] = torch.cat((rot, trans[..., None]), -1).cpu().numpy()


def solve_default(problem: Problem, timings: dict[str, float]) -> SolveState:
    """Run the default optimiser; returns the final state (poses, mapped landmarks)."""
    settings = problem.settings
    state = SolveState.empty(problem)
    tick = time.perf_counter()
    if problem.subject is not None and len(state.hand_frames):
        state.hand_pose[state.hand_frames] = initial_hand(problem, state.hand_frames)
        timings["hand_init"] = time.perf_counter() - tick
        fit_hand(problem, state, None, settings.lm_iterations, ROBUST_ROUNDS)
    timings["hand_keypoints"] = time.perf_counter() - tick - timings.get("hand_init", 0.0)
    tick = time.perf_counter()
    if problem.objects:
        _solve_objects(problem, state)
    timings["objects_keypoints"] = time.perf_counter() - tick
    robust_mm = settings.depth_robust_mm if settings.robust else None
    for _ in range(settings.icp_rounds if problem.clouds else 0):
        tick = time.perf_counter()
        matches = state.match_all(problem)
        state.matches = matches
        timings["depth_matching"] = timings.get("depth_matching", 0.0) + time.perf_counter() - tick
        tick = time.perf_counter()
        if problem.subject is not None and len(state.hand_frames):
            depth = problem.depth_data(len(problem.objects),
                                       [matches[f] for f in state.hand_frames], problem.hand_faces,
                                       robust_mm)
            fit_hand(problem, state, depth, settings.lm_iterations, 1, smooth=True)
        for o in range(len(problem.objects)):
            depth = problem.depth_data(o, matches, problem.object_faces[o], robust_mm)
            fit_object(problem, state, o, state.tables[o], depth, settings.lm_iterations, 2)
        timings["depth_refine"] = timings.get("depth_refine", 0.0) + time.perf_counter() - tick
    return state


def _solve_objects(problem: Problem, state: SolveState) -> None:
    """Map landmarks at frame 0 (the given poses), solve, map the rest from the solved poses,
    and solve again with all of them."""
    hand_at = state.hand_at(problem)
    initial = problem.initial_poses
    state.landmarks = map_landmarks(problem, state.landmarks,
                                    lambda f: initial if f == 0 else None, hand_at)
    for second_pass in (False, True):
        if second_pass:
            before = [list(v) for v in state.landmarks]
            state.landmarks = map_landmarks(problem, state.landmarks,
                                            lambda f: state.object_poses[:, f], hand_at)
            if before == state.landmarks:
                break
        for o in range(len(problem.objects)):
            table = mapped_table(problem, o, state.landmarks[o])
            state.tables[o] = table
            if not second_pass:
                state.object_poses[o] = initial_object_poses(problem, o, table)
            fit_object(problem, state, o, table, None, problem.settings.lm_iterations,
                       ROBUST_ROUNDS)

