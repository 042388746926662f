"""Depth scale and pixel shift of each view's aligned depth, against the calibrated rig.

The shift ``(dx, dy)`` (``corrected(q) = maps(q + shift) / s``) is the one that puts the
depth map's edges on its own colour image's edges. The scale ``s``: each view's corrected
depth is back-projected to world points through the (refined) calibration, which the
triangulated labels pin, and compared with what the other views' depth sees at those points'
pixels (median over the views); the scale whose points agree best wins.

Why not the depth at the labelled pixels: a hand joint lies inside the finger, and at its
pixel the depth camera sees the skin, a fingertip's edge, the object or the table; on
synthetic captures the median joint-to-surface offset of a joint varies from -138 to +88 mm
between views, which buries a 1 % scale (7 mm at 0.7 m) and a 2 px shift. Whole depth maps
against each other see every surface two views share (table, objects, hand). Across views a
shift and a scale look alike on a tilted table, so the shift comes from the colour image.

Depth maps are (F, H, W) uint16 mm (0 = no depth), indexed by the view's own frames; a view
with time offset ``k`` (see :mod:`worker.rig.common`) shows world time ``t`` at frame ``t + k``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from worker.geometry.cameras import CameraModel, camera_to_world, pixels_to_rays

# Residuals beyond this (mm) count as this much: surfaces one view sees and the other does not.
CAP_MM = 20.0
# A non-zero shift must score 1 / SHIFT_GAIN times no shift's edge score.
SHIFT_GAIN = 0.9
SHIFT_RADIUS_PX = 4
# A depth edge: neighbours this far apart (mm), as the synthetic sensor's and D415's edges.
EDGE_JUMP_MM = 15.0
MAX_SCALE_ERROR = 0.04
GRID_STEP_PX = 6
SAMPLE_FRAMES = 3


@dataclass(frozen=True)
class DepthFit:
    """One view's estimate: ``scale`` s (1 = calibrated), ``shift_px`` (dx, dy) ints,
    ``cost_mm`` the capped mean disagreement with the other views at the estimate and
    ``cost_mm_before`` at scale 1 and no shift."""

    scale: float
    shift_px: tuple[int, int]
    cost_mm: float
    cost_mm_before: float


def _grid(camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """Sample pixels (N, 2) int of a regular grid and their rays (N, 3), z = 1."""
    xs = np.arange(GRID_STEP_PX // 2, camera.width, GRID_STEP_PX)
    ys = np.arange(GRID_STEP_PX // 2, camera.height, GRID_STEP_PX)
    q = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    return q, pixels_to_rays(q.astype(np.float64), camera.K, camera.dist)


def _world_points(camera: CameraModel, depth: np.ndarray, grid: tuple[np.ndarray, np.ndarray],
                  shift: tuple[int, int], scale: float) -> np.ndarray:
    """World points (N, 3) m of one depth map (H, W) mm corrected by shift and scale; NaN
    where there is no depth."""
    q, rays = grid
    src = q + np.asarray(shift)
    h, w = depth.shape
    inside = (src[:, 0] >= 0) & (src[:, 0] < w) & (src[:, 1] >= 0) & (src[:, 1] < h)
    d = np.zeros(len(q))
    d[inside] = depth[src[inside, 1], src[inside, 0]]
    z = np.where(d > 0, d / 1000.0 / scale, np.nan)
    return camera_to_world(rays * z[:, None], camera.T_cam_to_world)


def _bilinear(depth: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Depth (N,) mm at sub-pixel positions uv (N, 2), bilinear; 0 where any of the four
    neighbours has no depth or lies outside the image (a depth edge or a hole)."""
    h, w = depth.shape
    out = np.zeros(len(uv))
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(uv).all(axis=1) & (uv[:, 0] >= 0) & (uv[:, 0] < w - 1) & \
            (uv[:, 1] >= 0) & (uv[:, 1] < h - 1)
    x0 = np.floor(uv[ok, 0]).astype(int)
    y0 = np.floor(uv[ok, 1]).astype(int)
    fx, fy = uv[ok, 0] - x0, uv[ok, 1] - y0
    corners = np.stack([depth[y0, x0], depth[y0, x0 + 1], depth[y0 + 1, x0],
                        depth[y0 + 1, x0 + 1]]).astype(np.float64)
    value = (corners[0] * (1 - fx) * (1 - fy) + corners[1] * fx * (1 - fy)
             + corners[2] * (1 - fx) * fy + corners[3] * fx * fy)
    out[ok] = np.where((corners > 0).all(axis=0), value, 0.0)
    return out


def _disagreement(points: np.ndarray, others: list[tuple[CameraModel, np.ndarray]]) -> np.ndarray:
    """(N,) capped |depth predicted - depth seen| mm, the median over the other views that
    have depth there (NaN where none has): robust to another faulty view among them."""
    diffs = np.full((len(points), len(others)), np.nan)
    for i, (camera, depth) in enumerate(others):
        with np.errstate(invalid="ignore"):
            z = camera.depth_of(points) * 1000.0
            seen = _bilinear(depth, camera.project(points))
        has = (seen > 0) & (z > 0)
        diffs[has, i] = np.minimum(np.abs(z[has] - seen[has]), CAP_MM)
    out = np.full(len(points), np.nan)
    any_view = np.isfinite(diffs).any(axis=1)
    out[any_view] = np.nanmedian(diffs[any_view], axis=1)
    return out


def _cost(camera: CameraModel, frames: list[tuple[np.ndarray, list[tuple[CameraModel,
          np.ndarray]]]], grid: tuple[np.ndarray, np.ndarray], shift: tuple[int, int],
          scale: float) -> float:
    """Mean capped disagreement (mm) over the sampled frames; a point no other view checks
    does not count."""
    costs = [_disagreement(_world_points(camera, own, grid, shift, scale), others)
             for own, others in frames]
    joined = np.concatenate(costs)
    return float(np.nanmean(joined)) if np.isfinite(joined).any() else float("inf")


Frames = list[tuple[np.ndarray, list[tuple[CameraModel, np.ndarray]]]]


def _best_scale(cost: Callable[[tuple[int, int], float], float], shift: tuple[int, int]
                ) -> tuple[float, float]:
    """(scale, cost) coarse to fine within 1 +- MAX_SCALE_ERROR at a given shift."""
    scale, best = 1.0, cost(shift, 1.0)
    for spacing in (0.01, 0.0025, 0.000625):
        trials = scale + spacing * np.arange(-4, 5)
        trials = trials[np.abs(trials - 1.0) <= MAX_SCALE_ERROR]
        costs = [cost(shift, float(s)) for s in trials]
        if min(costs) < best:
            scale, best = float(trials[int(np.argmin(costs))]), min(costs)
    return scale, best


def _edge_strength(color: np.ndarray) -> np.ndarray:
    """(H, W) float gradient magnitude of a colour (H, W, 3) or grey (H, W) image."""
    grey = color.astype(np.float32)
    if grey.ndim == 3:
        grey = grey.mean(axis=2)
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3)
    return np.hypot(gx, gy)


def _depth_edges(depth: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels next to a jump of more than EDGE_JUMP_MM between valid depths."""
    d = depth.astype(np.float64)
    edge = np.zeros(d.shape, bool)
    jx = (np.abs(np.diff(d, axis=1)) > EDGE_JUMP_MM) & (d[:, 1:] > 0) & (d[:, :-1] > 0)
    jy = (np.abs(np.diff(d, axis=0)) > EDGE_JUMP_MM) & (d[1:] > 0) & (d[:-1] > 0)
    edge[:, 1:] |= jx
    edge[:, :-1] |= jx
    edge[1:] |= jy
    edge[:-1] |= jy
    return edge


def registration_shift(depth: np.ndarray, color: dict[int, np.ndarray]) -> tuple[int, int]:
    """The (dx, dy) px within SHIFT_RADIUS_PX that puts the depth's edges on the colour's.

    For a shift s the corrected depth's edges lie at q where the raw edges lie at q + s; the
    score is the mean colour gradient under them. Object and hand silhouettes are edges in
    both, whatever the depth scale, so the shift is found apart from the scale. (0, 0) unless
    the best shift scores 1 / SHIFT_GAIN times as high.

    depth: (F, H, W) uint16 mm; color: {frame index: (H, W, 3) or (H, W) uint8} of the
    same view, a few frames are enough.
    """
    r = SHIFT_RADIUS_PX
    scores = np.zeros((2 * r + 1, 2 * r + 1))
    for f, image in color.items():
        if not 0 <= f < len(depth):
            continue
        grad = _edge_strength(image)
        edges = _depth_edges(depth[f])
        h, w = edges.shape
        inner = grad[r:h - r, r:w - r]
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                shifted = edges[r + dy:h - r + dy, r + dx:w - r + dx]
                scores[dy + r, dx + r] += inner[shifted].sum() / max(1, int(shifted.sum()))
    best = np.unravel_index(int(np.argmax(scores)), scores.shape)
    if scores[best] * SHIFT_GAIN <= scores[r, r]:
        return (0, 0)
    return (int(best[1]) - r, int(best[0]) - r)


def _search(camera: CameraModel, frames: Frames, grid: tuple[np.ndarray, np.ndarray],
            shift: tuple[int, int]) -> DepthFit:
    """The scale at the given shift, coarse to fine."""
    before = _cost(camera, frames, grid, (0, 0), 1.0)
    scale, best = _best_scale(lambda s, k: _cost(camera, frames, grid, s, k), shift)
    return DepthFit(scale, shift, best, before)


def _frames_of(view: int, cameras: list[CameraModel], own_maps: np.ndarray,
               maps: list[np.ndarray | None], offsets: np.ndarray) -> Frames:
    """SAMPLE_FRAMES world times every view with depth has: (the view's own map, [(camera,
    map)] of the other views from ``maps``)."""
    have = [v for v, m in enumerate(maps) if m is not None]
    lengths = [len(maps[v]) for v in have]  # type: ignore[arg-type]
    lo = max(max(0, -int(offsets[v])) for v in have)
    hi = min(n - max(0, int(offsets[v])) for v, n in zip(have, lengths, strict=True))
    times = np.unique(np.linspace(lo, hi - 1, SAMPLE_FRAMES).round().astype(int))
    out: Frames = []
    for t in times:
        own = own_maps[t + int(offsets[view])]
        others = [(cameras[v], maps[v][t + int(offsets[v])])  # type: ignore[index]
                  for v in have if v != view]
        out.append((own, others))
    return out


def fit_depth(cameras: list[CameraModel], depth: list[np.ndarray | None],
              offsets: np.ndarray, color: list[dict[int, np.ndarray]] | None = None,
              passes: int = 2) -> list[DepthFit | None]:
    """Per view, its depth scale and shift against the other views (None without depth).

    Args:
        cameras: V views as (re)calibrated. depth: V maps (F, H, W) uint16 mm or None.
        offsets: (V,) whole-frame time offsets. color: per view {frame: (H, W, 3) uint8}
            of a few frames; the shift is found only where a view has some (else (0, 0)).
        passes: the second pass judges each view's own maps against the others' maps
            corrected by the first pass's estimates.
    """
    fits: list[DepthFit | None] = [None] * len(cameras)
    if sum(m is not None for m in depth) < 2:
        return fits
    shifts = [(0, 0)] * len(cameras)
    for v, (own, images) in enumerate(zip(depth, color or [{}] * len(cameras), strict=True)):
        if own is not None and images:
            shifts[v] = registration_shift(own, images)
    maps = list(depth)
    for _ in range(passes):
        fits = [None if own is None else
                _search(camera, _frames_of(v, cameras, own, maps, offsets), _grid(camera),
                        shifts[v])
                for v, (camera, own) in enumerate(zip(cameras, depth, strict=True))]
        maps = [None if m is None or f is None else correct_depth(m, f.scale, f.shift_px)
                for m, f in zip(depth, fits, strict=True)]
    return fits


def view_scale_fit(view: int, cameras: list[CameraModel], depth: list[np.ndarray | None],
                   offsets: np.ndarray, shift_px: tuple[int, int] = (0, 0)) -> DepthFit:
    """One view's depth scale at a given shift under ``cameras``, against the other views'
    maps as they are (see fit_depth); its ``cost_mm`` says how well that pose and scale
    explain what the others see."""
    own = depth[view]
    if own is None:
        raise ValueError(f"view {view} has no depth")
    camera = cameras[view]
    return _search(camera, _frames_of(view, cameras, own, depth, offsets), _grid(camera),
                   shift_px)


def correct_depth(maps: np.ndarray, scale: float, shift_px: tuple[int, int]) -> np.ndarray:
    """A view's depth maps (F, H, W) uint16 mm re-registered and re-scaled: out(q) =
    maps(q + shift) / scale; pixels whose source lies outside the image read 0 (no depth)."""
    dx, dy = shift_px
    out = np.zeros_like(maps)
    h, w = maps.shape[1:]
    src = maps[:, max(0, dy):h + min(0, dy), max(0, dx):w + min(0, dx)]
    out[:, max(0, -dy):h - max(0, dy), max(0, -dx):w - max(0, dx)] = src
    scaled = np.rint(out.astype(np.float64) / scale)
    return np.where(out > 0, np.clip(scaled, 1, 65535), 0).astype(np.uint16)
