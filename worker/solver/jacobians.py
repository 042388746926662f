"""The hand's Jacobian by the chain rule, for Levenberg-Marquardt.

Every factor is in closed form (forward-mode autodiff through the residuals cost tens of
times more: each op against a constant took ~0.3 ms under it): MANO's forward kinematics gives
the joints' and the matched vertices' derivatives (`SubjectHand.pose_jacobian`), each projected
joint depends on its own 3D position (`Rig.project_derivative`), each depth residual linearly
on its triangle's corners. Rows follow `energies.hand_residuals`: keypoints, regulariser,
depth, smoothness of joints and pose.

For a depth point matched inside a triangle the residual is n . (p - c); its Jacobian here
keeps the normal n fixed (the usual point-to-plane linearisation). At the matching pose p - c
is parallel to n, so the dropped term (p - c) . dn vanishes there; LM accepts steps on the exact
residuals, so the approximation costs at most a little convergence speed.
"""

from __future__ import annotations

import torch

from worker.hand.lbs import axis_angle_to_matrix_derivative
from worker.hand.posing import SubjectHand
from worker.solver.energies import MM_PER_M, DepthData, HandData, ObjectData
from worker.solver.projection import Rig, pose_matrix, transform


def hand_jacobian(hand: SubjectHand, rig: Rig, pose_m: torch.Tensor, data: HandData
                  ) -> torch.Tensor:
    """(B, M, 51) Jacobian of `energies.hand_residuals` w.r.t. pose_m (B, 51)."""
    batch = pose_m.shape[0]
    depth = data.depth
    ids = depth.vertex_ids if depth is not None else pose_m.new_zeros(0).long()
    joints, vertices, d_joints, d_vertices = hand.pose_jacobian(pose_m, ids)
    d_pixels = rig.project_derivative(joints)  # (B, V, 21, 2, 3)
    parts = [(data.sqrt_w[..., None, None] * (d_pixels @ d_joints[:, None])).flatten(1, 3)]
    pca = torch.zeros(45, pose_m.shape[1], dtype=pose_m.dtype, device=pose_m.device)
    pca[:, 3:48] = torch.eye(45, dtype=pose_m.dtype, device=pose_m.device)  # d theta_pca
    parts.append((pca * data.sqrt_reg).expand(batch, -1, -1))
    if depth is not None:
        parts.append(_depth_jacobian(vertices, d_vertices, depth))
    if data.smooth_target is not None and data.sqrt_smooth is not None:
        parts.append((d_joints * MM_PER_M * data.sqrt_smooth[:, None, None, None]).flatten(1, 2))
    if data.pose_target is not None and data.sqrt_pose_smooth is not None:
        parts.append(pca * data.sqrt_pose_smooth[:, None, None])
    return torch.cat(parts, dim=1)


def rigid_point_derivatives(delta: torch.Tensor, base: torch.Tensor, points: torch.Tensor
                            ) -> torch.Tensor:
    """(B, N, 3, 6) derivative of object points posed by `projection.pose_matrix(delta, base)`
    with respect to delta (B, 6) (axis-angle on the left, then translation); points (N, 3) or
    (B, N, 3), object frame."""
    d_rot = axis_angle_to_matrix_derivative(delta[:, :3])  # (B, 3, 3, 3): [..., i] = dR/dw_i
    local = points @ base[:, :3, :3].transpose(-1, -2)  # R_base m: (B, N, 3)
    d_omega = torch.einsum("brci,bnc->bnri", d_rot, local)
    eye = torch.eye(3, dtype=delta.dtype, device=delta.device)
    return torch.cat((d_omega, eye.expand(*local.shape[:2], 3, 3)), dim=-1)


def object_jacobian(delta: torch.Tensor, data: ObjectData) -> torch.Tensor:
    """(B, M, 6) Jacobian of `energies.object_residuals` w.r.t. delta (B, 6), in closed form
    (the landmarks' projection, the depth rows as for the hand)."""
    rot, trans = pose_matrix(delta, data.base)
    parts = []
    if data.vertex_ids.numel():
        model = data.vertices[data.vertex_ids]
        landmarks = transform(rot, trans, model)
        d_points = rigid_point_derivatives(delta, data.base, model)  # (B, L, 3, 6)
        d_pixels = data.rig.project_each_derivative(landmarks, data.views)  # (B, L, 2, 3)
        parts.append((data.sqrt_w[..., None, None] * (d_pixels @ d_points)).flatten(1, 2))
    depth = data.depth
    if depth is not None:
        model = data.vertices[depth.vertex_ids]  # (B, K, 3)
        parts.append(_depth_jacobian(transform(rot, trans, model),
                                     rigid_point_derivatives(delta, data.base, model), depth))
    if not parts:
        return delta.new_zeros(delta.shape[0], 0, 6)
    return torch.cat(parts, dim=1)


def _depth_jacobian(vertices: torch.Tensor, d_vertices: torch.Tensor, depth: DepthData
                    ) -> torch.Tensor:
    """(B, 3N, P) rows of the depth residuals from posed vertices (B, K, 3) and their
    derivatives (B, K, 3, P)."""
    rows = torch.arange(vertices.shape[0], device=vertices.device)[:, None, None]
    corners = vertices[rows, depth.corners]  # (B, N, 3, 3)
    d_corners = d_vertices[rows, depth.corners]  # (B, N, 3, 3, P)
    d_offset = -(depth.bary[..., None, None] * d_corners).sum(2)  # (B, N, 3, P)
    normal = torch.linalg.cross(corners[..., 1, :] - corners[..., 0, :],
                                corners[..., 2, :] - corners[..., 0, :])
    normal = normal / normal.norm(dim=-1, keepdim=True).clamp(min=1e-12)
    d_signed = (normal[..., None] * d_offset).sum(2, keepdim=True)  # (B, N, 1, P)
    d_plane = torch.cat((d_signed, torch.zeros_like(d_offset[:, :, :2])), dim=2)
    d_res = torch.where(depth.interior[..., None, None], d_plane, d_offset)
    return (d_res * (MM_PER_M * depth.sqrt_w)[..., None, None]).flatten(1, 2)
