"""Starting points: the hand from triangulated keypoints, objects from their landmarks.

Hand: DLT-triangulate the labelled joints (robustly reweighted), align the subject's mean hand
to the palm joints (Kabsch: rotation and translation), then fit the 45 pose coefficients to the
3D joints with Levenberg-Marquardt. Objects: a linear multi-view pose from the mapped
landmarks where a frame has enough of them, else the previous frame's pose (frame 0: the given
initial pose). World frame, metres.
"""

from __future__ import annotations

import numpy as np
import torch

from worker.geometry.transforms import matrix_to_axis_angle
from worker.solver.lm import levenberg_marquardt
from worker.solver.problem import MappedLandmarks, Problem
from worker.solver.triangulate import linear_poses, reprojection_px, triangulate

# DexYCB indices of the wrist and the four fingers' MCP joints: the rigid part of the palm.
PALM_JOINTS = (0, 5, 9, 13, 17)
# Weight (per rad^2) of the pose prior while fitting 3D joints, against residuals in mm.
INIT_PRIOR = 1.0
# Landmark observations a frame needs for worker.solver.triangulate.linear_poses to accept its
# pose (12 unknowns of [R | t], 2 equations per observation).
LINEAR_POSE_OBSERVATIONS = 6


def kabsch(source: np.ndarray, target: np.ndarray, weight: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """R (B, 3, 3), t (B, 3) minimising sum w ||R s + t - x||^2.

    source, target: (B, N, 3) points; weight: (B, N).
    """
    w = weight[..., None] / np.maximum(weight.sum(1), 1e-12)[:, None, None]
    mu_s, mu_t = (w * source).sum(1), (w * target).sum(1)
    cov = np.einsum("bn,bni,bnj->bij", weight, target - mu_t[:, None], source - mu_s[:, None])
    u, _, vt = np.linalg.svd(cov)
    sign = np.sign(np.linalg.det(u @ vt))
    fix = np.stack([np.ones_like(sign), np.ones_like(sign), sign], axis=1)
    rot = (u * fix[:, None, :]) @ vt
    return rot, mu_t - np.einsum("bij,bj->bi", rot, mu_s)


def initial_hand(problem: Problem, frames: np.ndarray, iterations: int = 10) -> np.ndarray:
    """pose_m (B, 51) for frames (B,), from the triangulated keypoints."""
    points, ok = triangulate(problem.cameras, problem.keypoints[:, frames],
                             problem.gamma[:, frames], problem.settings.robust_scale_px)
    return hand_from_joints(problem, points, ok, iterations)


def hand_from_joints(problem: Problem, points: np.ndarray, ok: np.ndarray,
                     iterations: int = 10) -> np.ndarray:
    """pose_m (B, 51) fitted to 3D joints: points (B, 21, 3) world metres, ok (B, 21) bool
    where a joint is known (a frame needs 3 of them, the palm's or any)."""
    subject = problem.require_subject()
    count = len(points)
    zero = torch.zeros(1, 51, dtype=torch.float64, device=problem.device)
    rest = subject.pose(zero)[0][0].cpu().numpy()  # (21, 3) mean hand, identity rotation
    palm = list(PALM_JOINTS)
    # The palm alone where at least 3 of its joints are seen, else every triangulated joint.
    weight = ok[:, palm].astype(np.float64)
    few = weight.sum(1) < 3
    weight[few] = 0.0
    w_all = np.concatenate([weight, np.where(few[:, None], ok, 0.0)], axis=1)
    src = np.concatenate([rest[palm], rest])[None].repeat(count, 0)
    tgt = np.nan_to_num(np.concatenate([points[:, palm], points], axis=1))
    rot, trans = kabsch(src, tgt, w_all)
    wrist = subject.rest_joints[0].cpu().numpy()
    pose = np.zeros((count, 51))
    pose[:, :3] = matrix_to_axis_angle(rot)
    pose[:, 48:] = trans + rot @ wrist - wrist
    target = problem.tensor(np.nan_to_num(points))
    mask = problem.tensor(ok.astype(np.float64))[..., None]

    none = torch.zeros(0, dtype=torch.long, device=problem.device)
    prior = torch.zeros(45, 51, dtype=torch.float64, device=problem.device)
    prior[:, 3:48] = INIT_PRIOR * torch.eye(45, dtype=torch.float64, device=problem.device)

    def residuals(p: torch.Tensor) -> torch.Tensor:
        joints, _ = subject.pose(p, none)
        offsets = ((joints - target) * mask * 1000.0).flatten(1)
        return torch.cat((offsets, p[:, 3:48] * INIT_PRIOR), dim=1)

    def jacobian(p: torch.Tensor) -> torch.Tensor:
        d_joints = subject.pose_jacobian(p, none)[2]  # (B, 21, 3, 51)
        offsets = (d_joints * mask[..., None] * 1000.0).flatten(1, 2)
        return torch.cat((offsets, prior.expand(len(p), -1, -1)), dim=1)

    fitted, _ = levenberg_marquardt(residuals, problem.tensor(pose), iterations,
                                    jacobian_fn=jacobian)
    return fitted.cpu().numpy()


def initial_object_poses(problem: Problem, index: int, marks: MappedLandmarks) -> np.ndarray:
    """(F, 3, 4) starting poses of object `index` over all frames: the linear pose where it
    reprojects the frame's landmarks better (median px) than the previous frame's start,
    else that previous start; frame 0 keeps the given initial pose."""
    frames = problem.num_frames
    poses = np.repeat(problem.initial_poses[index][None], frames, axis=0)
    if not len(marks.views):
        return poses
    model = problem.object_vertices[index][marks.vertices]
    # The linear pose only of frames with enough observations to be taken (linear_poses'
    # rule); elsewhere it has no solution (no landmark seen: 0 / 0) and is never used.
    enough = np.flatnonzero(marks.gamma.sum(axis=1) >= LINEAR_POSE_OBSERVATIONS)
    linear = np.full((frames, 3, 4), np.nan)
    ok = np.zeros(frames, bool)
    linear_error = np.full(frames, np.inf)
    if enough.size:
        linear[enough], ok[enough] = linear_poses(problem.cameras, marks.views, model,
                                                  marks.xy[enough], marks.gamma[enough])
        linear_error[enough] = _median_errors(problem, marks, model, linear[enough],
                                              enough.tolist())
    for f in range(1, frames):
        if ok[f] and linear_error[f] < _median_errors(problem, marks, model, poses[f - 1][None],
                                                      [f])[0]:
            poses[f] = linear[f]
        else:
            poses[f] = poses[f - 1]
    return poses


def _median_errors(problem: Problem, marks: MappedLandmarks, model: np.ndarray,
                   poses: np.ndarray, frames: list[int] | None = None) -> np.ndarray:
    """(B,) median reprojection error px of the seen landmarks under poses (B, 3, 4) at frames
    (default: all frames, B = F); inf where a frame sees none, or where none of its seen
    landmarks projects (a NaN pose, a point on a camera's principal plane)."""
    frames = list(range(len(poses))) if frames is None else frames
    world = np.einsum("bij,lj->bli", poses[:, :, :3], model) + poses[:, None, :, 3]
    errors = np.stack([reprojection_px([problem.cameras[v]], world[:, k],
                                       marks.xy[frames, k][None])[0]
                       for k, v in enumerate(marks.views)], axis=1)
    errors = np.where(marks.gamma[frames], errors, np.nan)
    out = np.full(len(poses), np.inf)
    measured = np.isfinite(errors).any(axis=1)
    out[measured] = np.nanmedian(errors[measured], axis=1)
    return out
