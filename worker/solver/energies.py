"""Energy terms as weighted residual vectors, batched over frames (PyTorch, differentiable).

Every term is written as residuals r with E = sum(r^2), so one definition serves Adam (which
minimises the sum) and Gauss-Newton / Levenberg-Marquardt (which needs r and its Jacobian).
Per frame, for one target (the hand, or one object):
  E_kpt   = w_kpt / sum(gamma) * sum gamma ||proj(X) - p||^2        px^2
  E_depth = w_depth / N_D * sum_i ||d_i - closest_i||^2              mm^2 (N_D: all matched points)
  E_reg   = w_reg * ||theta_pca||^2                                  rad^2 (hand only)
  E_pose_smooth = w_smooth_pose * ||theta_pca - mean of its neighbours'||^2   rad^2 (hand only)
The square roots of the weights (including any robust reweighting) are folded into the `sqrt_w`
tensors, so the functions here only evaluate geometry. Frames: world; lengths metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from worker.hand.posing import SubjectHand
from worker.solver.projection import Rig, pose_matrix, transform

MM_PER_M = 1000.0


@dataclass
class DepthData:
    """Matched depth points of B frames, padded to N: points (B, N, 3) world m; vertex_ids
    (B, K) the mesh vertices each frame's matches touch (padded); corners (B, N, 3) indices
    into that frame's vertex_ids of each match's triangle; bary (B, N, 3); sqrt_w (B, N), 0 on
    padding; interior (B, N) bool, the closest point lies inside its triangle (not on an edge
    or a corner)."""

    points: torch.Tensor
    vertex_ids: torch.Tensor
    corners: torch.Tensor
    bary: torch.Tensor
    sqrt_w: torch.Tensor
    interior: torch.Tensor


@dataclass
class HandData:
    """keypoints (B, V, 21, 2) px (NaN-free, zeros where unlabelled); sqrt_w (B, V, 21);
    sqrt_reg: scalar sqrt(w_reg); depth: DepthData or None; smooth_target: (B, 21, 3) joints
    the frame is pulled towards (its neighbours' mean), or None; sqrt_smooth: (B,) the square
    root of each frame's smoothness weight (0 where a frame has no neighbour on both sides);
    pose_target: (B, 45) PCA pose coefficients the frame is pulled towards (its neighbours'
    mean), or None, with per-frame weights sqrt_pose_smooth (B,) as for the joints."""

    keypoints: torch.Tensor
    sqrt_w: torch.Tensor
    sqrt_reg: float
    depth: DepthData | None
    smooth_target: torch.Tensor | None = None
    sqrt_smooth: torch.Tensor | None = None
    pose_target: torch.Tensor | None = None
    sqrt_pose_smooth: torch.Tensor | None = None


@dataclass
class ObjectData:
    """vertices (N, 3) object frame m; base (B, 3, 4) object-to-world the increments act on;
    views (L,) and vertex_ids (L,) of the mapped landmarks; xy (B, L, 2) px; sqrt_w (B, L);
    rig: the cameras the landmarks are seen by."""

    vertices: torch.Tensor
    base: torch.Tensor
    views: torch.Tensor
    vertex_ids: torch.Tensor
    xy: torch.Tensor
    sqrt_w: torch.Tensor
    depth: DepthData | None
    rig: Rig


def depth_residuals(vertices: torch.Tensor, depth: DepthData) -> torch.Tensor:
    """(B, 3N) weighted signed distances, mm, of the depth points to the posed vertices
    (B, K, 3) listed in depth.vertex_ids.

    Where the closest point is inside its triangle the signed distance is n . (p - c) along
    the triangle's unit normal n (one residual, two zeros); on an edge or a corner it is the
    offset p - c itself (three residuals). Either way the squared residual is the squared
    distance, and in the first case moving the mesh along its own surface costs nothing, as
    with the true distance field, which is what lets Gauss-Newton slide into place.
    """
    batch = torch.arange(vertices.shape[0], device=vertices.device)[:, None, None]
    corners = vertices[batch, depth.corners]  # (B, N, 3 corners, 3)
    closest = (depth.bary[..., None] * corners).sum(-2)
    offset = depth.points - closest
    normal = torch.linalg.cross(corners[..., 1, :] - corners[..., 0, :],
                                corners[..., 2, :] - corners[..., 0, :])
    normal = normal / normal.norm(dim=-1, keepdim=True).clamp(min=1e-12)
    signed = (offset * normal).sum(-1, keepdim=True)
    plane = torch.cat((signed, torch.zeros_like(offset[..., :2])), dim=-1)
    residual = torch.where(depth.interior[..., None], plane, offset)
    return (residual * MM_PER_M * depth.sqrt_w[..., None]).flatten(1)


def keypoint_residuals(projected: torch.Tensor, target: torch.Tensor,
                       sqrt_w: torch.Tensor) -> torch.Tensor:
    """(B, 2K) weighted reprojection offsets, px: projected, target (B, ..., 2), sqrt_w (B, ...)."""
    return ((projected - target) * sqrt_w[..., None]).flatten(1)


def hand_residuals(hand: SubjectHand, rig: Rig, pose_m: torch.Tensor, data: HandData
                   ) -> torch.Tensor:
    """(B, M) residuals of the hand for pose_m (B, 51): keypoints, regulariser, depth, joint
    smoothness, pose smoothness (the last two where given)."""
    ids = data.depth.vertex_ids if data.depth is not None else pose_m.new_zeros(0).long()
    joints, vertices = hand.pose(pose_m, ids)
    parts = [keypoint_residuals(rig.project(joints), data.keypoints, data.sqrt_w),
             pose_m[:, 3:48] * data.sqrt_reg]
    if data.depth is not None:
        parts.append(depth_residuals(vertices, data.depth))
    if data.smooth_target is not None and data.sqrt_smooth is not None:
        parts.append(((joints - data.smooth_target) * MM_PER_M
                      * data.sqrt_smooth[:, None, None]).flatten(1))
    if data.pose_target is not None and data.sqrt_pose_smooth is not None:
        parts.append((pose_m[:, 3:48] - data.pose_target) * data.sqrt_pose_smooth[:, None])
    return torch.cat(parts, dim=1)


def object_residuals(delta: torch.Tensor, data: ObjectData) -> torch.Tensor:
    """(B, M) residuals of one object for pose increments delta (B, 6): landmarks, depth."""
    rot, trans = pose_matrix(delta, data.base)
    parts = []
    if data.vertex_ids.numel():
        landmarks = transform(rot, trans, data.vertices[data.vertex_ids])  # (B, L, 3)
        parts.append(keypoint_residuals(rig_project_each(data, landmarks), data.xy, data.sqrt_w))
    depth = data.depth
    if depth is not None:
        parts.append(depth_residuals(transform(rot, trans, data.vertices[depth.vertex_ids]),
                                     depth))  # vertices[(B, K)] is (B, K, 3)
    if not parts:
        return delta.new_zeros(delta.shape[0], 0)
    return torch.cat(parts, dim=1)


def rig_project_each(data: ObjectData, points: torch.Tensor) -> torch.Tensor:
    """(B, L, 2) px: landmark l of points (B, L, 3) projected into its own view data.views[l]."""
    return data.rig.project_each(points, data.views)


def energy(residuals: torch.Tensor) -> torch.Tensor:
    """(B,) per-frame energy sum(r^2) of residuals (B, M)."""
    return (residuals * residuals).sum(dim=1)
