"""Linear blend skinning in PyTorch, with MANO/SMPL semantics.

All functions are batched (batch dimension first), differentiable, and keep the dtype and device
of their inputs. Lengths are metres; rotations are axis-angle vectors in radians (direction = the
axis, norm = the angle) or 3x3 rotation matrices acting on column vectors.
"""

from __future__ import annotations

import torch

from worker import torch_threads

torch_threads.apply(torch)

# Below this squared angle (rad^2) the Rodrigues coefficients use their Taylor series: at
# theta^2 = 1e-6 the first dropped term is ~1e-20, far below float64 resolution of the result.
_SMALL_ANGLE_SQ = 1e-6
# Below this squared angle the derivative's coefficients use their Taylor series: their closed
# forms subtract nearly equal terms (at t = 0.01 the series' first dropped term is ~1e-13).
_SMALL_DERIVATIVE_SQ = 1e-4


def skew(vectors: torch.Tensor) -> torch.Tensor:
    """(..., 3) vectors -> (..., 3, 3) cross-product matrices [v]x with [v]x @ u = v x u."""
    x, y, z = vectors.unbind(-1)
    zero = torch.zeros_like(x)
    rows = (
        torch.stack((zero, -z, y), dim=-1),
        torch.stack((z, zero, -x), dim=-1),
        torch.stack((-y, x, zero), dim=-1),
    )
    return torch.stack(rows, dim=-2)


def axis_angle_to_matrix(axis_angle: torch.Tensor) -> torch.Tensor:
    """Rodrigues' formula: (..., 3) axis-angle, radians -> (..., 3, 3) rotation matrices.

    R = I + a K + b K^2 with K = [r]x, a = sin(t)/t, b = (1 - cos t)/t^2, t = |r|. Near t = 0
    the coefficients come from their Taylor series, so the value and the gradient are exact and
    finite at (and around) zero rotation.
    """
    if axis_angle.shape[-1] != 3:
        raise ValueError(f"axis_angle must have shape (..., 3), got {tuple(axis_angle.shape)}")
    theta_sq = (axis_angle * axis_angle).sum(-1)
    small = theta_sq < _SMALL_ANGLE_SQ
    # Keep the unused branch finite so that torch.where does not leak NaN gradients.
    safe_sq = torch.where(small, torch.ones_like(theta_sq), theta_sq)
    theta = safe_sq.sqrt()
    a = torch.where(small, 1.0 - theta_sq / 6.0 + theta_sq**2 / 120.0, torch.sin(theta) / theta)
    b = torch.where(
        small, 0.5 - theta_sq / 24.0 + theta_sq**2 / 720.0, (1.0 - torch.cos(theta)) / safe_sq
    )
    k = skew(axis_angle)
    eye = torch.eye(3, dtype=axis_angle.dtype, device=axis_angle.device)
    return eye + a[..., None, None] * k + b[..., None, None] * (k @ k)


def axis_angle_to_matrix_derivative(axis_angle: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3, 3) derivative of :func:`axis_angle_to_matrix`: [..., i] = dR / dr_i.

    With s = t^2 and R = I + a(s) K + b(s) K^2: dR/dr_i = 2 r_i (a'(s) K + b'(s) K^2)
    + a E_i + b (E_i K + K E_i), E_i = [e_i]x. Below _SMALL_DERIVATIVE_SQ a' and b' come from
    their Taylor series (the closed forms lose digits to cancellation there).
    """
    theta_sq = (axis_angle * axis_angle).sum(-1)
    small = theta_sq < _SMALL_ANGLE_SQ
    safe_sq = torch.where(small, torch.ones_like(theta_sq), theta_sq)
    theta = safe_sq.sqrt()
    sin, cos = torch.sin(theta), torch.cos(theta)
    a = torch.where(small, 1.0 - theta_sq / 6.0 + theta_sq**2 / 120.0, sin / theta)
    b = torch.where(small, 0.5 - theta_sq / 24.0 + theta_sq**2 / 720.0, (1.0 - cos) / safe_sq)
    series = theta_sq < _SMALL_DERIVATIVE_SQ
    safe = torch.where(series, torch.ones_like(theta_sq), theta_sq).sqrt()
    s_sin, s_cos = torch.sin(safe), torch.cos(safe)
    da = torch.where(series, -1.0 / 6.0 + theta_sq / 60.0,
                     (safe * s_cos - s_sin) / (2.0 * safe**3))
    db = torch.where(series, -1.0 / 24.0 + theta_sq / 360.0,
                     (safe * s_sin - 2.0 * (1.0 - s_cos)) / (2.0 * safe**4))
    k = skew(axis_angle)[..., None, :, :]  # (..., 1, 3, 3), against E_i (3, 3, 3)
    basis = skew(torch.eye(3, dtype=axis_angle.dtype, device=axis_angle.device))

    def per_axis(x: torch.Tensor) -> torch.Tensor:
        return x[..., None, None, None]

    along = (2.0 * axis_angle)[..., None, None] * (per_axis(da) * k + per_axis(db) * (k @ k))
    d = along + per_axis(a) * basis + per_axis(b) * (basis @ k + k @ basis)
    return d.movedim(-3, -1)


def blend_shapes(betas: torch.Tensor, shapedirs: torch.Tensor) -> torch.Tensor:
    """Shape offsets: betas (B, K) and shapedirs (V, 3, K) -> (B, V, 3) metres."""
    return torch.einsum("bk,vck->bvc", betas, shapedirs)


def rigid_transforms(
    rotations: torch.Tensor, joints: torch.Tensor, parents: list[int]
) -> tuple[torch.Tensor, torch.Tensor]:
    """Pose a kinematic chain.

    rotations: (B, J, 3, 3) each joint's rotation relative to its parent.
    joints: (B, J, 3) rest joint positions, metres, model frame.
    parents: J parent indices, -1 for the root, every parent before its children.
    Returns posed joints (B, J, 3) metres, and (B, J, 4, 4) transforms that map a rest-frame
    point attached to joint j to its posed position (world transform of j composed with the
    inverse of j's rest placement), as linear blend skinning needs.
    """
    rel = joints.clone()
    rel[:, 1:] = joints[:, 1:] - joints[:, parents[1:]]
    bottom = rotations.new_zeros((*rotations.shape[:2], 1, 4))
    bottom[..., 0, 3] = 1.0
    local = torch.cat((torch.cat((rotations, rel[..., None]), dim=-1), bottom), dim=-2)
    chain = [local[:, 0]]
    for j in range(1, len(parents)):
        chain.append(chain[parents[j]] @ local[:, j])
    world = torch.stack(chain, dim=1)
    posed_joints = world[:, :, :3, 3]
    # Subtract R_world @ J_rest so that the transform acts on rest-frame coordinates.
    offset = (world[:, :, :3, :3] @ joints[..., None])[..., 0]
    skinning = world.clone()
    skinning[:, :, :3, 3] = posed_joints - offset
    return posed_joints, skinning


def linear_blend_skinning(
    vertices: torch.Tensor, transforms: torch.Tensor, weights: torch.Tensor
) -> torch.Tensor:
    """Skin vertices (B, V, 3) with per-joint transforms (B, J, 4, 4) and weights (V, J) or
    (B, V, J).

    Returns (B, V, 3): sum_j w_vj (R_j v + t_j), metres. Blending the 3x4 transforms is one
    plain matrix product, which stays fast under vmap (the solver's Jacobians).
    """
    blended = (weights @ transforms[:, :, :3, :].flatten(2)).unflatten(-1, (3, 4))
    return (blended[..., :3] * vertices[..., None, :]).sum(-1) + blended[..., 3]


def pose_features(rotations: torch.Tensor) -> torch.Tensor:
    """(B, 16, 3, 3) joint rotations -> (B, 135) pose-corrective features (R_j - I), j = 1..15."""
    eye = torch.eye(3, dtype=rotations.dtype, device=rotations.device)
    return (rotations[:, 1:] - eye).flatten(1)
