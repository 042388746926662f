"""Batched projection through stacked cameras and Levenberg-Marquardt refinement of points.

Conventions as in worker.geometry.cameras: pixels x right and y down, world frame in metres,
OpenCV (k1, k2, p1, p2, k3) lens distortion. Used by worker.geometry.triangulate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.geometry.distortion import distort, distort_jacobian

LM_ITERATIONS = 12

@dataclass(frozen=True)
class CameraStack:
    """V cameras as stacked arrays: rot (V, 3, 3) and trans (V, 3) world-to-camera (metres),
    K (V, 3, 3) pixels, dist (V, 5) OpenCV coefficients (zeros for an ideal pinhole),
    centres (V, 3) camera centres in world metres."""

    rot: np.ndarray
    trans: np.ndarray
    K: np.ndarray
    dist: np.ndarray
    centres: np.ndarray

    @classmethod
    def of(cls, cameras: list[CameraModel]) -> CameraStack:
        if not cameras or not all(isinstance(c, CameraModel) for c in cameras):
            raise ValueError("cameras must be a non-empty list of CameraModel")
        rot_c2w = np.stack([c.T_cam_to_world[:, :3] for c in cameras])
        centres = np.stack([c.T_cam_to_world[:, 3] for c in cameras])
        rot = np.transpose(rot_c2w, (0, 2, 1))
        trans = -np.einsum("vij,vj->vi", rot, centres)
        dist = np.stack([np.zeros(5) if c.dist is None else c.dist for c in cameras])
        return cls(rot, trans, np.stack([c.K for c in cameras]), dist, centres)

    @property
    def projections(self) -> np.ndarray:
        """(V, 3, 4) normalised projection matrices [R | t] (world -> undistorted z=1 plane)."""
        return np.concatenate([self.rot, self.trans[:, :, None]], axis=2)


def camera_frames(stack: CameraStack, points: np.ndarray) -> np.ndarray:
    """World points (..., 3) -> camera frames (..., V, 3), metres, as one matrix product."""
    v = len(stack.rot)
    with np.errstate(invalid="ignore"):
        flat = points.reshape(-1, 3) @ stack.rot.transpose(2, 0, 1).reshape(3, 3 * v)
    return flat.reshape(points.shape[:-1] + (v, 3)) + stack.trans


def project_stack(stack: CameraStack, points: np.ndarray,
                  jacobian: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Project world points into every camera of the stack.

    Args:
        stack: V cameras.
        points: (N, 3) world metres (or (N, V, 3): one point per view).
        jacobian: also return d pixel / d point.

    Returns:
        pixels (N, V, 2), camera depth z (N, V) metres, and the Jacobian (N, V, 2, 3) or None;
        pixels and Jacobian are NaN where a point lies on a camera's principal plane (z = 0,
        e.g. at the centre of the master camera, the world origin): it has no image there.
        Points behind a camera (z < 0) project as OpenCV does; callers test z.
    """
    if points.ndim == 3:
        cam = np.einsum("vij,nvj->nvi", stack.rot, points) + stack.trans
    else:
        cam = camera_frames(stack, points)
    z = cam[..., 2]
    inv_z = np.divide(1.0, z, out=np.full_like(z, np.nan), where=z != 0)
    x, y = cam[..., 0] * inv_z, cam[..., 1] * inv_z
    distorted = bool(stack.dist.any())
    xd, yd = distort(x, y, stack.dist) if distorted else (x, y)
    K = stack.K
    u = K[:, 0, 0] * xd + K[:, 0, 1] * yd + K[:, 0, 2]
    v = K[:, 1, 1] * yd + K[:, 1, 2]
    pix = np.stack([u, v], axis=-1)
    if not jacobian:
        return pix, z, None
    jn = np.zeros(x.shape + (2, 3))
    jn[..., 0, 0] = jn[..., 1, 1] = inv_z
    jn[..., 0, 2] = -x * inv_z
    jn[..., 1, 2] = -y * inv_z
    if not distorted:
        return pix, z, K[:, :2, :2] @ (jn @ stack.rot)
    jac = K[:, :2, :2] @ distort_jacobian(x, y, stack.dist) @ (jn @ stack.rot)
    return pix, z, jac


def reprojection_errors(stack: CameraStack, pixels: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, V) pixel distance between observations (N, V, 2) and projected points (N, 3); NaN
    where unobserved (or the point is NaN), +inf where the point is behind the camera."""
    pix, z, _ = project_stack(stack, points)
    err = np.linalg.norm(pix - pixels, axis=-1)
    observed = np.isfinite(pixels).all(axis=-1) & np.isfinite(points).all(axis=-1)[:, None]
    err = np.where(z > 0, err, np.inf)
    return np.where(observed, err, np.nan)


def cauchy_weights(errors: np.ndarray, scales: np.ndarray | None) -> np.ndarray:
    """IRLS weights 1 / (1 + (e / c)^2) of the Cauchy loss for errors (N, V) px at scales c
    (broadcast to (N, V)); ones where scales is None."""
    if scales is None:
        return np.ones_like(errors)
    return 1.0 / (1.0 + (errors / scales) ** 2)


def _weighted_cost(stack: CameraStack, pixels: np.ndarray, points: np.ndarray, mask: np.ndarray,
                   weights: np.ndarray, scales: np.ndarray | None = None) -> np.ndarray:
    """(n,) sum of w * rho(e) over the masked observations: rho = e^2, or the Cauchy loss
    c^2 log(1 + (e / c)^2) with scales c; infinite where a point falls behind a camera."""
    err = reprojection_errors(stack, pixels, points)
    err = np.where(mask, np.where(np.isfinite(err), err, np.inf), 0.0)
    rho = err ** 2 if scales is None else scales ** 2 * np.log1p((err / scales) ** 2)
    return np.where(mask, weights * rho, 0.0).sum(axis=1)


def _lm_step(stack: CameraStack, pixels: np.ndarray, x: np.ndarray, mask: np.ndarray,
             w: np.ndarray, damping: np.ndarray, scales: np.ndarray | None) -> np.ndarray:
    """One damped (iteratively re-weighted) Gauss-Newton step (n, 3) metres for x (n, 3)."""
    pix, _, jac = project_stack(stack, x, jacobian=True)
    assert jac is not None  # asked for
    res = np.where(mask[..., None], pix - pixels, 0.0)
    w = w * cauchy_weights(np.linalg.norm(res, axis=-1), scales)
    flat = jac.reshape(len(x), -1, 3)  # (n, 2V, 3)
    weighted = np.swapaxes(flat * np.repeat(w, 2, axis=1)[..., None], 1, 2)
    hess = weighted @ flat
    grad = (weighted @ res.reshape(len(x), -1, 1))[..., 0]
    diag = np.einsum("nii->ni", hess)
    lhs = hess + (damping[:, None] * diag)[:, :, None] * np.eye(3) + 1e-18 * np.eye(3)
    return np.linalg.solve(lhs, -grad[..., None])[..., 0]


def refine_points(stack: CameraStack, pixels: np.ndarray, points: np.ndarray, mask: np.ndarray,
                  weights: np.ndarray | None = None, scales: np.ndarray | None = None,
                  iterations: int = LM_ITERATIONS) -> np.ndarray:
    """Levenberg-Marquardt on the (distorted) pixel reprojection error, all points at once.

    Args:
        stack: V cameras.
        pixels: (N, V, 2) observations, px.
        points: (N, 3) starting points, world metres (NaN rows are left alone).
        mask: (N, V) bool, the observations that enter the cost.
        weights: (N, V) or (V,) non-negative weights of the squared errors (default 1).
        scales: (N, V) or (V,) Cauchy scales in px for a robust cost (default: least squares);
            an observation c px off weighs half, one 3c off a tenth, so a minority inside the
            inlier threshold no longer drags the point.
        iterations: LM steps; each point keeps its own damping and only accepts improving steps.

    Returns:
        (N, 3) refined world points, metres.
    """
    w = np.broadcast_to(np.ones(mask.shape[1]) if weights is None else weights, mask.shape)
    w = np.where(mask, w, 0.0)
    c = None if scales is None else np.broadcast_to(scales, mask.shape)
    active = np.flatnonzero(np.isfinite(points).all(axis=1) & (mask.sum(axis=1) >= 2))
    x = points.copy()
    damping = np.full(len(x), 1e-3)
    cost = np.full(len(x), np.inf)

    def part(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        return pixels[rows], mask[rows], w[rows], None if c is None else c[rows]

    pix_a, mask_a, w_a, c_a = part(active)
    cost[active] = _weighted_cost(stack, pix_a, x[active], mask_a, w_a, c_a)
    for _ in range(iterations):
        if active.size == 0:
            break
        pix_a, mask_a, w_a, c_a = part(active)
        step = _lm_step(stack, pix_a, x[active], mask_a, w_a, damping[active], c_a)
        trial = x[active] + step
        new_cost = _weighted_cost(stack, pix_a, trial, mask_a, w_a, c_a)
        better = new_cost < cost[active]
        x[active[better]], cost[active[better]] = trial[better], new_cost[better]
        damping[active] = np.where(better, damping[active] / 3.0, damping[active] * 4.0)
        # A point stops once its step is below a nanometre or its damping has run away
        # (no improving step left: it sits at the minimum up to rounding).
        moving = (np.linalg.norm(step, axis=1) > 1e-9) & (damping[active] < 1e6)
        active = active[moving]
    return x
