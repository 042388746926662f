"""Triangulation of labelled keypoints in the solver's (view-first) layout, and a linear
multi-view pose estimate for rigid objects. NumPy, float64; world frame, metres; pixels."""

from __future__ import annotations

import numpy as np

from worker.geometry.cameras import CameraModel, pixels_to_rays, project_points
from worker.geometry.triangulate import triangulate_dlt, triangulate_points


def _world_to_cam(cameras: list[CameraModel]) -> np.ndarray:
    """(V, 3, 4) world-to-camera [R | t] of each view."""
    out = []
    for c in cameras:
        rot = c.T_cam_to_world[:, :3].T
        out.append(np.hstack([rot, -(rot @ c.T_cam_to_world[:, 3])[:, None]]))
    return np.stack(out)


def reprojection_px(cameras: list[CameraModel], points: np.ndarray,
                    pixels: np.ndarray) -> np.ndarray:
    """(V, ...) pixel distance between points (..., 3) projected into each view and pixels
    (V, ..., 2)."""
    return np.stack([np.linalg.norm(project_points(points, c.K, c.T_cam_to_world, c.dist) - px,
                                    axis=-1) for c, px in zip(cameras, pixels, strict=True)])


def triangulate(cameras: list[CameraModel], pixels: np.ndarray, mask: np.ndarray,
                robust_scale_px: float | None = 8.0) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate points seen in V views (worker.geometry.triangulate, in the solver's layout).

    pixels: (V, ..., 2) px; mask: (V, ...) bool, which observations to use.
    robust_scale_px: None for the plain linear DLT of every used observation; otherwise the
        robust triangulation (view-pair hypotheses, outliers beyond twice this scale rejected,
        Levenberg-Marquardt refinement with lens distortion).
    Returns points (..., 3) world metres (NaN where fewer than 2 views) and a (...,) bool of
    where a point was triangulated.
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    mask = np.asarray(mask, dtype=bool) & np.isfinite(pixels).all(axis=-1)
    shape = mask.shape[1:]
    used = np.where(mask[..., None], pixels, np.nan)
    flat = np.moveaxis(used.reshape(len(cameras), -1, 2), 0, 1)  # (N, V, 2)
    if robust_scale_px:
        points = triangulate_points(cameras, flat, outlier_px=2.0 * robust_scale_px).points
    else:
        points = triangulate_dlt(cameras, flat)
    points = points.reshape((*shape, 3))
    ok = np.isfinite(points).all(axis=-1)
    return points, ok


def linear_poses(cameras: list[CameraModel], views: np.ndarray, model_points: np.ndarray,
                 pixels: np.ndarray, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Object-to-world poses of F frames from L landmarks, each one model point seen in one view.

    views: (L,) view ids; model_points: (L, 3) object frame, metres; pixels: (F, L, 2) px;
    seen: (F, L) bool. Per frame, the 12 entries of [R | t] are solved linearly (u r3.X' - r1.X'
    = 0 per observation in its camera's normalised coordinates) and R is projected onto SO(3).
    Returns poses (F, 3, 4) and (F,) bool: at least 6 observations, a well-posed system and a
    non-zero solution (a frame without one has a NaN translation).
    """
    frames = pixels.shape[0]
    xy = np.stack([pixels_to_rays(np.nan_to_num(pixels[:, k]), cameras[v].K, cameras[v].dist)
                   [:, :2] for k, v in enumerate(views)], axis=1)  # (F, L, 2)
    proj = _world_to_cam(cameras)[views]  # (L, 3, 4)
    homo = np.hstack([model_points, np.ones((len(views), 1))])
    # camera point = Rc (A X_h) + tc with A = [R | t]; linear in vec(A) (row-major).
    blocks = np.einsum("kij,kl->kijl", proj[:, :, :3], homo).reshape(len(views), 3, 12)
    const = proj[:, :, 3]
    rows = np.concatenate([xy[..., 0, None] * blocks[:, 2] - blocks[:, 0],
                           xy[..., 1, None] * blocks[:, 2] - blocks[:, 1]], axis=1)
    rhs = np.concatenate([const[:, 0] - xy[..., 0] * const[:, 2],
                          const[:, 1] - xy[..., 1] * const[:, 2]], axis=1)
    weight = np.concatenate([seen, seen], axis=1).astype(np.float64)
    normal = np.einsum("fm,fmi,fmj->fij", weight, rows, rows)
    ok = (seen.sum(1) >= 6) & (np.linalg.cond(normal) < 1e12)
    normal[~ok] = np.eye(12)
    sol = np.linalg.solve(normal, np.einsum("fm,fmi,fm->fi", weight, rows, rhs)[..., None])
    pose = sol[..., 0].reshape(frames, 3, 4)
    u, s, vt = np.linalg.svd(pose[:, :, :3])
    fix = np.ones((frames, 3))
    fix[:, 2] = np.sign(np.linalg.det(u @ vt))
    rot = (u * fix[:, None, :]) @ vt
    # The linear solution's scale error lives in its singular values; rescale t with them. A
    # zero solution (no landmark seen, or seen only from cameras whose centre is the world
    # origin: a system with no constant term) has no scale: its translation is NaN, not ok.
    scale = s.mean(axis=1, keepdims=True)
    trans = np.divide(pose[:, :, 3], scale, out=np.full((frames, 3), np.nan), where=scale > 0)
    ok &= scale[:, 0] > 0
    return np.concatenate([rot, trans[..., None]], axis=2), ok
