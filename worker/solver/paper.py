"""The paper's optimiser (DexYCB, Chao et al. 2021), kept as the reference.

Frame by frame, in order: warm-start every pose from the previous frame's solution and run
Adam (learning rate 0.01, 100 iterations) on E = E_depth + E_kpt + E_reg of all targets at
once, the depth points' closest points on the union of meshes recomputed every
`rematch_every` iterations (1: every iteration, as the paper's AABB-tree SDF is). Landmarks are
mapped to vertices on reaching their first visible frame, from the warm-start poses.
Unlabelled hand frames leave the hand out (its last pose carries over as the next start). The very
first hand pose, which the paper does not specify, comes from the same triangulation-based
start the default optimiser uses.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from worker.solver.energies import DepthData, energy, hand_residuals, object_residuals
from worker.solver.init import initial_hand
from worker.solver.mapping import map_landmarks, mapped_table
from worker.solver.problem import Problem
from worker.solver.projection import pose_matrix
from worker.solver.state import SolveState, hand_vertices_world


def solve_paper(problem: Problem, timings: dict[str, float]) -> SolveState:
    """Run the reference optimiser over all frames; returns the final state."""
    state = SolveState.empty(problem)
    labelled = problem.labelled
    hand_pose = None
    poses = problem.initial_poses.copy()
    timings.setdefault("depth_matching", 0.0)
    for frame in range(problem.num_frames):
        solve_hand = problem.subject is not None and bool(labelled[frame])
        if solve_hand and hand_pose is None:
            tick = time.perf_counter()
            hand_pose = initial_hand(problem, np.array([frame]))[0]
            timings["hand_init"] = time.perf_counter() - tick
        _map_new_landmarks(problem, state, frame, poses, hand_pose if solve_hand else None)
        hand_pose, poses = _solve_frame(problem, state, frame, hand_pose if solve_hand else None,
                                        poses, problem.settings.paper_rematch_every, timings)
        if solve_hand:
            state.hand_pose[frame] = hand_pose
        if problem.objects:
            state.object_poses[:, frame] = poses
    return state


def _map_new_landmarks(problem: Problem, state: SolveState, frame: int, poses: np.ndarray,
                       hand_pose: np.ndarray | None) -> None:
    if not problem.objects:
        return
    hand = None if hand_pose is None else hand_vertices_world(problem, hand_pose[None])[0]
    state.landmarks = map_landmarks(problem, state.landmarks,
                                    lambda f: poses if f == frame else None,
                                    lambda f: hand if f == frame else None)
    state.tables = [mapped_table(problem, o, v) for o, v in enumerate(state.landmarks)]


def _solve_frame(problem: Problem, state: SolveState, frame: int, hand_pose: np.ndarray | None,
                 poses: np.ndarray, rematch_every: int, timings: dict[str, float]
                 ) -> tuple[np.ndarray | None, np.ndarray]:
    """Adam on one frame; returns the new hand pose (or the input) and object poses (O, 3, 4)."""
    settings = problem.settings
    frames = np.array([frame])
    hand = None if hand_pose is None else torch.nn.Parameter(problem.tensor(hand_pose[None]))
    deltas = torch.nn.Parameter(torch.zeros(len(poses), 6, dtype=torch.float64,
                                            device=problem.device))
    params = ([hand] if hand is not None else []) + ([deltas] if len(poses) else [])
    if not params:
        return hand_pose, poses
    optimiser = torch.optim.Adam(params, lr=settings.lr)
    depth: list[DepthData | None] = [None] * (len(poses) + 1)
    for step in range(settings.paper_iterations):
        if problem.clouds and step % rematch_every == 0:
            tick = time.perf_counter()
            depth = _depth_now(problem, state, frame, hand, deltas, poses)
            timings["depth_matching"] += time.perf_counter() - tick
        optimiser.zero_grad()
        total = torch.zeros((), dtype=torch.float64, device=problem.device)
        if hand is not None:
            hand_data = problem.hand_data(frames, None, depth[-1])
            residuals = hand_residuals(problem.require_subject(), problem.rig, hand, hand_data)
            total = total + energy(residuals).sum()
        for o in range(len(poses)):
            object_data = problem.object_data(o, frames, poses[o][None], state.tables[o], None,
                                              depth[o])
            total = total + energy(object_residuals(deltas[o:o + 1], object_data)).sum()
        total.backward()
        optimiser.step()
    return _finish(hand, hand_pose, deltas, poses, problem)


def _current_poses(problem: Problem, deltas: torch.Tensor, poses: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        rot, trans = pose_matrix(deltas, problem.tensor(poses))
    return torch.cat((rot, trans[..., None]), -1).cpu().numpy()


def _depth_now(problem: Problem, state: SolveState, frame: int, hand: torch.Tensor | None,
               deltas: torch.Tensor, poses: np.ndarray) -> list[DepthData | None]:
    """DepthData per mesh (objects, then the hand) matched against the current estimate."""
    current = _current_poses(problem, deltas, poses) if len(poses) else poses
    verts = None if hand is None else hand_vertices_world(problem, hand.detach().cpu().numpy())[0]
    matches = [problem.match_depth(frame, verts, current)]
    if state.matches is None:
        state.matches = [None] * problem.num_frames
    state.matches[frame] = matches[0]
    out = [problem.depth_data(o, matches, problem.object_faces[o]) for o in range(len(poses))]
    out.append(problem.depth_data(len(poses), matches, problem.hand_faces)
               if hand is not None else None)
    return out


def _finish(hand: torch.Tensor | None, hand_pose: np.ndarray | None, deltas: torch.Tensor,
            poses: np.ndarray, problem: Problem) -> tuple[np.ndarray | None, np.ndarray]:
    new_hand = hand_pose if hand is None else hand.detach().cpu().numpy()[0]
    new_poses = _current_poses(problem, deltas, poses) if len(poses) else poses
    return new_hand, new_poses
