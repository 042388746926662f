"""Shared steps of the rig estimates: checked inputs, time shifts and leave-one-out points.

Shapes: V views, F frames, P points per frame. ``keypoints`` (V, F, P, 2) image pixels (x right,
y down), NaN where there is no label; ``visible`` (V, F, P) bool. World frame in metres.
A view's time offset ``k`` (whole frames) means its frame index ``f`` shows the scene at
world time ``f - k`` (``k = 1``: the camera is one frame late).
"""

from __future__ import annotations

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.geometry.triangulate import triangulate_points

# An observation further than this from the consensus of the other views is an outlier for
# the triangulation (px): well above careful labels (2 px) and calibration faults (~10 px).
OUTLIER_PX = 25.0


def observed(keypoints: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """(V, F, P, 2) px with NaN wherever the point is not labelled visible."""
    return np.where(visible[..., None], keypoints, np.nan)


def check_tracks(cameras: list[CameraModel], keypoints: np.ndarray,
                 visible: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float64 keypoints (V, F, P, 2) and bool visible (V, F, P); ValueError naming shapes."""
    keypoints = np.asarray(keypoints, dtype=np.float64)
    visible = np.asarray(visible, dtype=bool)
    if keypoints.ndim != 4 or keypoints.shape[-1] != 2 or keypoints.shape[0] != len(cameras):
        raise ValueError(f"keypoints must have shape (V={len(cameras)}, F, P, 2), "
                         f"got {keypoints.shape}")
    if visible.shape != keypoints.shape[:3]:
        raise ValueError(f"visible must have shape {keypoints.shape[:3]}, got {visible.shape}")
    if len(cameras) < 3:
        raise ValueError(f"rig health needs at least 3 views, got {len(cameras)}")
    return keypoints, visible & np.isfinite(keypoints).all(axis=-1)


def shift_frames(track: np.ndarray, offset: int, fill: float | bool = np.nan) -> np.ndarray:
    """One view's (F, ...) array re-indexed to world time: out[t] = track[t + offset]."""
    out = np.full_like(track, fill)
    frames = len(track)
    lo, hi = max(0, -offset), min(frames, frames - offset)
    if hi > lo:
        out[lo:hi] = track[lo + offset:hi + offset]
    return out


def align_views(keypoints: np.ndarray, visible: np.ndarray,
                offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All views' tracks re-indexed to world time by their offsets (V,) whole frames."""
    kp = np.stack([shift_frames(keypoints[v], int(k)) for v, k in enumerate(offsets)])
    vis = np.stack([shift_frames(visible[v], int(k), False) for v, k in enumerate(offsets)])
    return kp, vis


def triangulate_views(cameras: list[CameraModel], pixels: np.ndarray,
                      views: list[int]) -> np.ndarray:
    """Points (F, P, 3) world metres triangulated robustly from ``views`` only; NaN where
    fewer than 2 of them agree. pixels: (V, F, P, 2) px, NaN where unobserved."""
    obs = np.moveaxis(pixels[views], 0, 2)  # (F, P, v, 2)
    shape = obs.shape[:2]
    tri = triangulate_points([cameras[v] for v in views], obs.reshape(-1, len(views), 2),
                             outlier_px=OUTLIER_PX)
    return tri.points.reshape(shape + (3,))


def leave_one_out_points(cameras: list[CameraModel], pixels: np.ndarray, view: int) -> np.ndarray:
    """(F, P, 3) world metres triangulated from every view except ``view``."""
    return triangulate_views(cameras, pixels, [v for v in range(len(cameras)) if v != view])


def reprojection_px(camera: CameraModel, points: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Distance (...) px between ``pixels`` (..., 2) and the projection of ``points`` (..., 3);
    NaN where either is missing or the point is behind the camera."""
    with np.errstate(invalid="ignore"):
        proj = camera.project(points)
        err = np.linalg.norm(proj - pixels, axis=-1)
        return np.where(camera.depth_of(points) > 0, err, np.nan)
