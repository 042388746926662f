"""The solve entry point: validate, run the chosen optimiser, report poses and residuals."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import torch

from worker.hand import HandLayer, builtin_hand_model
from worker.hand.params import check_side
from worker.hand.posing import posed_hand
from worker.solver.confidence import object_confidence
from worker.solver.default import solve_default
from worker.solver.hand_confidence import hand_confidence
from worker.solver.initial_pose import fit_initial_pose
from worker.solver.paper import solve_paper
from worker.solver.problem import Problem
from worker.solver.state import SolveState
from worker.solver.types import SolveInputs, SolveResult, SolveSettings
from worker.solver.validate import check_inputs


def solve(inputs: SolveInputs, settings: SolveSettings | None = None) -> SolveResult:
    """Fit the hand's MANO pose and the objects' 6D poses in every frame (world frame).

    An object without an initial pose gets one fitted to frame 0's depth and landmarks
    (`worker.solver.initial_pose`). Raises ValueError (naming the field and its actual shape)
    on unusable input, including an object without an initial pose whose fit fails (naming it
    and why); RuntimeError if settings.device is CUDA and none exists.
    """
    settings = settings or SolveSettings()
    check_inputs(inputs, settings)
    if settings.device.startswith("cuda") and not torch.cuda.is_available():
        raise RuntimeError(f"device {settings.device!r} was asked for but CUDA is not available")
    start = time.perf_counter()
    timings: dict[str, float] = {}
    inputs = with_initial_poses(inputs, settings)
    timings["initial_fit"] = time.perf_counter() - start
    problem = Problem(inputs, settings)
    timings["setup"] = time.perf_counter() - start
    if settings.optimiser == "paper":
        state = solve_paper(problem, timings)
    else:
        state = solve_default(problem, timings)
    tick = time.perf_counter()
    result = _result(problem, state, timings)
    timings["residuals"] = time.perf_counter() - tick
    timings["total"] = time.perf_counter() - start
    timings["per_frame"] = timings["total"] / problem.num_frames
    return result


def with_initial_poses(inputs: SolveInputs, settings: SolveSettings) -> SolveInputs:
    """The inputs with every missing initial pose fitted to frame 0's depth and landmarks
    (`initial_pose`); ValueError naming the object and why where that fit fails."""
    objects = []
    for i, obj in enumerate(inputs.objects):
        if obj.initial_pose is None:
            depth: list[np.ndarray | None] = list(inputs.depth) if settings.use_depth \
                else [None] * len(inputs.cameras)
            fit = fit_initial_pose(inputs.cameras, depth, obj.vertices, obj.faces,
                                   obj.landmarks, settings.seed)
            if fit.pose is None:
                raise ValueError(
                    f"objects[{i}] ({obj.name}) has no initial pose and none could be fitted "
                    f"to frame 0: {fit.reason}; give its pose at frame 0 (initial_pose, a 3x4 "
                    "object-to-world matrix)")
            obj = dataclasses.replace(obj, initial_pose=fit.pose)
        objects.append(obj)
    return dataclasses.replace(inputs, objects=objects)


def _result(problem: Problem, state: SolveState, timings: dict[str, float]) -> SolveResult:
    frames, views = problem.num_frames, len(problem.cameras)
    pose = np.full((frames, 51), np.nan)
    joints = np.full((frames, 21, 3), np.nan)
    errors = np.full((frames, views, 21), np.nan)
    labelled = problem.labelled.copy()
    if problem.subject is not None and len(state.hand_frames):
        hf = state.hand_frames
        pose[hf] = state.hand_pose[hf]
        joints[hf] = state.joints(problem)
        errors[hf] = np.moveaxis(state.hand_errors(problem), 0, 1)
    depth_rms = state.depth_rms_mm(problem) if problem.clouds else np.full(frames, np.nan)
    trust = object_confidence(problem, state)
    hand_trust, hand_flags = np.zeros(0), list[str | None]()
    if problem.hand is not None:
        hand_trust, hand_flags = hand_confidence(problem.hand.evidence, problem.gamma, labelled,
                                                 list(problem.reasons), errors, depth_rms)
    return SolveResult(
        hand_pose_m=pose, hand_joints=joints, object_poses=state.object_poses.copy(),
        labelled=labelled, reasons=list(problem.reasons), kpt_error_px=errors,
        depth_rms_mm=depth_rms, landmark_vertices=[list(v) for v in state.landmarks],
        landmark_points=[[problem.object_vertices[o][v].tolist() if v >= 0 else None
                          for v in ids] for o, ids in enumerate(state.landmarks)],
        timings=timings,
        betas=None if problem.subject is None else problem.betas.copy(),
        side=None if problem.hand is None else problem.hand.side,
        object_confidence=trust.confidence, object_flags=trust.flags,
        hand_confidence=hand_trust, hand_flags=hand_flags)


def hand_vertices(result: SolveResult, inputs: SolveInputs, frame: int) -> np.ndarray:
    """(V, 3) world vertices, metres, of the solved hand at `frame` (V = the model's, 778 for
    MANO). Raises ValueError if the frame has no hand solution."""
    if inputs.hand is None or not 0 <= frame < len(result.labelled) or not result.labelled[frame]:
        raise ValueError(f"frame {frame} has no hand solution")
    model = inputs.hand_model or builtin_hand_model(check_side(inputs.hand.side))
    vertices, _ = posed_hand(HandLayer(model), result.hand_pose_m[frame][None], inputs.hand.betas)
    return vertices[0]
