"""The default optimiser: all frames at once, Levenberg-Marquardt from triangulation.

Frames do not wait for each other: the hand starts from its triangulated joints in every frame
and is refined in one batch; objects rest at their initial pose until the evidence moves them
and are then held, fitted with a prior of moving with the palm (see `objects`). Keypoint residuals
are reweighted with a Cauchy loss (iteratively reweighted least squares) so that gross
labelling errors lose their pull; depth matches are renewed a few times (ICP-style rounds);
a smoothness term pulls each frame's joints towards its neighbours' mean in every round.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from worker.solver.energies import (
    DepthData,
    HandData,
    hand_residuals,
)
from worker.solver.init import initial_hand
from worker.solver.jacobians import hand_jacobian
from worker.solver.lm import cauchy_weights, levenberg_marquardt
from worker.solver.mapping import map_landmarks, mapped_table
from worker.solver.objects import palm_poses, refit_held, solve_motion
from worker.solver.problem import Problem
from worker.solver.state import SolveState

ROBUST_ROUNDS = 3


def fit_hand(problem: Problem, state: SolveState, depth: DepthData | None, iterations: int,
             rounds: int, pose_prior: tuple[np.ndarray, float] | None = None) -> None:
    """Refine state.hand_pose on the labelled frames in place.

    Each round renews the robust weights and, with settings.w_smooth > 0, the smoothness
    targets (each frame's neighbours' mean joints from the current poses), then runs LM; frames
    are independent within a round, so the smoothness couples them from round to round.
    pose_prior: (targets (B, 45) PCA pose coefficients, weight) pulling each frame's pose
    towards its target instead of towards its neighbours' mean (a frame fitted alone, whose
    neighbour is already known).
    """
    subject = problem.require_subject()
    frames = state.hand_frames
    settings = problem.settings
    for _ in range(rounds):
        robust = None
        if settings.robust:
            robust = cauchy_weights(np.moveaxis(state.hand_errors(problem), 0, 1),
                                    settings.robust_scale_px)
        data = problem.hand_data(frames, robust, depth)
        if settings.w_smooth > 0:
            target, inner = neighbour_mean(state.joints(problem), frames)
            data.smooth_target = problem.tensor(target)
            data.sqrt_smooth = problem.tensor(np.sqrt(settings.w_smooth) * inner)
        if pose_prior is not None:
            data.pose_target = problem.tensor(pose_prior[0])
            data.sqrt_pose_smooth = problem.tensor(np.full(len(frames), np.sqrt(pose_prior[1])))
        elif settings.w_smooth_pose > 0:
            target, inner = neighbour_mean(state.hand_pose[frames, 3:48], frames)
            data.pose_target = problem.tensor(target)
            data.sqrt_pose_smooth = problem.tensor(np.sqrt(settings.w_smooth_pose) * inner)

        def residuals(p: torch.Tensor, data: HandData = data) -> torch.Tensor:
            return hand_residuals(subject, problem.rig, p, data)

        def jacobian(p: torch.Tensor, data: HandData = data) -> torch.Tensor:
            return hand_jacobian(subject, problem.rig, p, data)

        pose, _ = levenberg_marquardt(residuals, problem.tensor(state.hand_pose[frames]),
                                      iterations, jacobian_fn=jacobian)
        state.hand_pose[frames] = pose.cpu().numpy()


def neighbour_mean(values: np.ndarray, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per labelled frame (B,) the mean (B, ...) of its two neighbours' values (joints, pose
    coefficients), and (B,) 1.0 where both neighbours (f - 1 and f + 1) are labelled, else 0.0
    (its own values).

    Pulling a frame towards its neighbours' mean penalises the second difference over time
    (acceleration), not the velocity: a hand moving or closing steadily is not held back. A
    frame at either end of a labelled run has only one neighbour, and pulling it towards that
    one would hold back its velocity, so it gets no pull.
    """
    index = {int(f): b for b, f in enumerate(frames)}
    out = values.copy()
    inner = np.zeros(len(frames))
    for b, f in enumerate(frames):
        before, after = index.get(int(f) - 1), index.get(int(f) + 1)
        if before is not None and after is not None:
            out[b] = 0.5 * (values[before] + values[after])
            inner[b] = 1.0
    return out, inner


def solve_default(problem: Problem, timings: dict[str, float]) -> SolveState:
    """Run the default optimiser; returns the final state (poses, mapped landmarks, motion)."""
    settings = problem.settings
    state = SolveState.empty(problem)
    tick = time.perf_counter()
    if problem.subject is not None and len(state.hand_frames):
        state.hand_pose[state.hand_frames] = initial_hand(problem, state.hand_frames)
        timings["hand_init"] = time.perf_counter() - tick
        fit_hand(problem, state, None, settings.lm_iterations, ROBUST_ROUNDS)
    timings["hand_keypoints"] = time.perf_counter() - tick - timings.get("hand_init", 0.0)
    tick = time.perf_counter()
    palm = palm_poses(problem, state)
    if problem.objects:
        _solve_objects(problem, state, palm)
    timings["objects"] = time.perf_counter() - tick
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
            fit_hand(problem, state, depth, settings.lm_iterations, 1)
            palm = palm_poses(problem, state)
        for o, motion in enumerate(state.motion):
            refit_held(problem, state, o, motion, matches, palm)
        timings["depth_refine"] = timings.get("depth_refine", 0.0) + time.perf_counter() - tick
    return state


def _solve_objects(problem: Problem, state: SolveState, palm: np.ndarray) -> None:
    """Map landmarks at frame 0 (the given poses), decide each object's rest and held frames
    and fit the held ones; then map the landmarks first seen later from those poses and fit
    again with all of them."""
    hand_at = state.hand_at(problem)
    initial = problem.initial_poses
    state.landmarks = map_landmarks(problem, state.landmarks,
                                    lambda f: initial if f == 0 else None, hand_at)
    state.object_poses[:] = initial[:, None]
    for second_pass in (False, True):
        if second_pass:
            before = [list(v) for v in state.landmarks]
            state.landmarks = map_landmarks(problem, state.landmarks,
                                            lambda f: state.object_poses[:, f], hand_at)
            if before == state.landmarks:
                break
        state.tables = [mapped_table(problem, o, v) for o, v in enumerate(state.landmarks)]
        state.motion = [solve_motion(problem, state, o, palm)
                        for o in range(len(problem.objects))]
