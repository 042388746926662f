"""Extrinsic corrections of views, by robust resection against the other views' points.

Block-coordinate bundle refinement: each view not in ``fixed`` is re-posed in turn by
Gauss-Newton (Cauchy-weighted, with a prior on the move) on its pixel error against the
points triangulated from all the other views, with outlier labels left out; a few sweeps let
the views settle together. The fixed views (the master, whose frame is the world) pin the
gauge. Conventions in :mod:`worker.geometry.cameras` and :mod:`worker.rig.common`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from worker.geometry.cameras import CameraModel
from worker.geometry.transforms import make_pose
from worker.rig.common import (
    leave_one_out_points,
    observed,
    reprojection_px,
    triangulate_views,
)

# Inliers of a resection: errors below max(MIN_INLIER_PX, INLIER_FACTOR x the median).
MIN_INLIER_PX = 6.0
INLIER_FACTOR = 3.0
MIN_POINTS = 12
# The fit: label noise (px) and the Cauchy scale of the robust loss; a Gaussian prior on the
# move away from the imported pose, wide against the faults it must find (0.5 deg, 5 mm) but
# enough to keep the directions the hand's small extent cannot fix (a rotation undone by a
# translation) at the imported pose instead of letting them wander.
SIGMA_PX = 2.0
CAUCHY_PX = 4.0
PRIOR_RAD = float(np.radians(0.5))
PRIOR_M = 0.005
GN_ITERATIONS = 10


@dataclass(frozen=True)
class ExtrinsicCorrection:
    """One view's correction: ``camera`` the refined view, ``rotation_deg`` and
    ``translation_mm`` how far its pose moved (angle of the relative rotation; distance between
    the camera centres), ``residual_px_before``/``after`` the median error of its labels against
    the other views' points under the imported and the refined poses, ``image_shift_px`` the
    mean distance between the labelled points' projections under the two poses: the part of
    the move the labels can see (a hand-sized cloud cannot tell a small rotation from a
    translation that undoes it in the image, so the degrees and millimetres alone are noisy)."""

    camera: CameraModel
    rotation_deg: float
    translation_mm: float
    residual_px_before: float
    residual_px_after: float
    image_shift_px: float


def posed(camera: CameraModel, params: np.ndarray) -> CameraModel:
    """``camera`` moved by params (6,): a rotation vector (rad, camera frame, applied after
    the world-to-camera rotation) and a camera-centre displacement (m, world)."""
    rot_w2c = cv2.Rodrigues(params[:3].reshape(3, 1))[0] @ camera.T_cam_to_world[:, :3].T
    return replace(camera, T_cam_to_world=make_pose(rot_w2c.T,
                                                    camera.T_cam_to_world[:, 3] + params[3:]))


def _residuals(camera: CameraModel, params: np.ndarray, points: np.ndarray,
               pixels: np.ndarray) -> np.ndarray:
    return (posed(camera, params).project(points) - pixels).ravel()


def _gauss_newton(camera: CameraModel, points: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Params (6,) minimising the Cauchy-weighted pixel error plus the prior on the move."""
    params = np.zeros(6)
    prior = np.repeat([1.0 / PRIOR_RAD, 1.0 / PRIOR_M], 3) ** 2
    for _ in range(GN_ITERATIONS):
        res = _residuals(camera, params, points, pixels)
        jac = np.empty((len(res), 6))
        for i in range(6):
            step = np.zeros(6)
            step[i] = 1e-7
            jac[:, i] = (_residuals(camera, params + step, points, pixels) - res) / 1e-7
        err = np.hypot(res[0::2], res[1::2])
        w = np.repeat(1.0 / (1.0 + (err / CAUCHY_PX) ** 2), 2) / SIGMA_PX ** 2
        lhs = (jac * w[:, None]).T @ jac + np.diag(prior)
        rhs = (jac * w[:, None]).T @ res + prior * params
        delta = np.linalg.solve(lhs, -rhs)
        params = params + delta
        if np.abs(delta).max() < 1e-9:
            break
    return params


def _resect(camera: CameraModel, anchor: CameraModel, points: np.ndarray,
            pixels: np.ndarray) -> CameraModel:
    """``anchor`` (the imported pose) re-posed against world points (N, 3) m and their
    pixels (N, 2) px, starting from and judging outliers by ``camera``."""
    ok = np.isfinite(points).all(axis=1) & np.isfinite(pixels).all(axis=1)
    points, pixels = points[ok], pixels[ok]
    err = reprojection_px(camera, points, pixels)
    inl = np.isfinite(err)
    if inl.sum() < MIN_POINTS:
        return camera
    inl &= err < max(MIN_INLIER_PX, INLIER_FACTOR * float(np.median(err[inl])))
    if inl.sum() < MIN_POINTS:
        return camera
    return posed(anchor, _gauss_newton(anchor, points[inl], pixels[inl]))


def pose_change(before: CameraModel, after: CameraModel) -> tuple[float, float]:
    """(degrees, mm): rotation angle between the two poses and distance between the centres."""
    rel = before.T_cam_to_world[:, :3].T @ after.T_cam_to_world[:, :3]
    cos = np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0)
    move = after.T_cam_to_world[:, 3] - before.T_cam_to_world[:, 3]
    return float(np.degrees(np.arccos(cos))), float(np.linalg.norm(move) * 1000.0)


def _median_residual(cameras: list[CameraModel], pixels: np.ndarray, view: int) -> float:
    err = reprojection_px(cameras[view], leave_one_out_points(cameras, pixels, view),
                          pixels[view])
    return float(np.nanmedian(err)) if np.isfinite(err).any() else float("nan")


def refine_extrinsics(cameras: list[CameraModel], keypoints: np.ndarray, visible: np.ndarray,
                      fixed: tuple[int, ...] = (0,), sweeps: int = 3
                      ) -> list[ExtrinsicCorrection]:
    """Per view, the refined pose and how far it moved.

    Args:
        cameras: V views. keypoints: (V, F, P, 2) px, already aligned in time. visible:
            (V, F, P) bool. fixed: views kept as they are (at least one: the gauge).
        sweeps: passes over the free views, worst first.

    Returns:
        V corrections (fixed views: unchanged, 0 deg and 0 mm).
    """
    if not fixed:
        raise ValueError("at least one view must stay fixed to pin the world frame")
    pixels = observed(keypoints, visible)
    before = [_median_residual(cameras, pixels, v) for v in range(len(cameras))]
    free = sorted((v for v in range(len(cameras)) if v not in fixed),
                  key=lambda v: -np.nan_to_num(before[v]))
    refined = list(cameras)
    for _ in range(sweeps):
        for view in free:
            points = leave_one_out_points(refined, pixels, view).reshape(-1, 3)
            refined[view] = _resect(refined[view], cameras[view], points,
                                    pixels[view].reshape(-1, 2))
    return describe_corrections(cameras, refined, pixels, before)


def describe_corrections(cameras: list[CameraModel], refined: list[CameraModel],
                         pixels: np.ndarray, before: list[float] | None = None
                         ) -> list[ExtrinsicCorrection]:
    """Per view, how far ``refined`` moved from ``cameras`` and its labels' residuals.

    pixels: (V, F, P, 2) px in world time, NaN where unlabelled. before: the views' median
    residuals (px) under ``cameras`` if already known.
    """
    if before is None:
        before = [_median_residual(cameras, pixels, v) for v in range(len(cameras))]
    points = triangulate_views(refined, pixels, list(range(len(cameras))))
    out = []
    for view, camera in enumerate(refined):
        deg, mm = pose_change(cameras[view], camera)
        seen = np.isfinite(pixels[view]).all(axis=-1) & np.isfinite(points).all(axis=-1)
        moved = reprojection_px(camera, points[seen], cameras[view].project(points[seen]))
        out.append(ExtrinsicCorrection(camera, deg, mm, before[view],
                                       _median_residual(refined, pixels, view),
                                       float(np.nanmean(moved)) if seen.any() else 0.0))
    return out
