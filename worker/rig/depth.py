"""Depth scale and pixel shift of each view's aligned depth, against the calibrated rig.

Each view's depth, corrected by a candidate scale ``s`` and shift ``(dx, dy)``
(``corrected(q) = maps(q + shift) / s``), is back-projected to world points through the
(refined) calibration, which the triangulated labels pin, and compared with what every other
view's depth sees at those points' pixels; the candidate whose points agree best wins.

Why not the depth at the labelled pixels: a hand joint lies inside the finger, and at its
pixel the depth camera sees the skin, a fingertip's edge, the object or the table; on
synthetic captures the median joint-to-surface offset of a joint varies from -138 to +88 mm
between views, which buries a 1 % scale (7 mm at 0.7 m) and a 2 px shift. Whole depth maps
against each other see every surface two views share (table, objects, hand).

Depth maps are (F, H, W) uint16 mm (0 = no depth), indexed by the view's own frames; a view
with time offset ``k`` (see :mod:`worker.rig.common`) shows world time ``t`` at frame ``t + k``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.cameras import CameraModel, camera_to_world, pixels_to_rays

# Residuals beyond this (mm) count as this much: surfaces one view sees and the other does not.
CAP_MM = 20.0
# A non-zero shift must lower the cost by this factor against no shift.
SHIFT_GAIN = 0.97
SHIFT_RADIUS_PX = 4
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


def _disagreement(points: np.ndarray, others: list[tuple[CameraModel, np.ndarray]]) -> np.ndarray:
    """(N,) capped |depth predicted - depth seen| mm, the best over the other views; NaN
    where no other view has depth there."""
    best = np.full(len(points), np.nan)
    for camera, depth in others:
        with np.errstate(invalid="ignore"):
            uv = np.rint(camera.project(points))
            z = camera.depth_of(points) * 1000.0
        ok = np.isfinite(uv).all(axis=1) & (z > 0)
        ok &= (uv[:, 0] >= 0) & (uv[:, 0] < depth.shape[1]) & (uv[:, 1] >= 0)
        ok &= uv[:, 1] < depth.shape[0]
        seen = np.zeros(len(points))
        idx = uv[ok].astype(int)
        seen[ok] = depth[idx[:, 1], idx[:, 0]]
        diff = np.where(seen > 0, np.minimum(np.abs(z - seen), CAP_MM), np.nan)
        best = np.fmin(best, diff)
    return best


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


def _search(camera: CameraModel, frames: Frames, grid: tuple[np.ndarray, np.ndarray]
            ) -> DepthFit:
    """Shift by coordinate descent over -R..R px at scale 1, then scale coarse to fine."""
    def cost(shift: tuple[int, int], scale: float = 1.0) -> float:
        return _cost(camera, frames, grid, shift, scale)

    before = cost((0, 0))
    shift, best = (0, 0), before
    for axis in (0, 1, 0):
        for step in range(-SHIFT_RADIUS_PX, SHIFT_RADIUS_PX + 1):
            trial = (step, shift[1]) if axis == 0 else (shift[0], step)
            c = cost(trial)
            if c < best:
                shift, best = trial, c
    if best >= SHIFT_GAIN * before:
        shift, best = (0, 0), before
    scale = 1.0
    for spacing in (0.01, 0.0025, 0.000625):
        trials = scale + spacing * np.arange(-4, 5)
        trials = trials[np.abs(trials - 1.0) <= MAX_SCALE_ERROR]
        costs = [cost(shift, float(s)) for s in trials]
        scale = float(trials[int(np.argmin(costs))])
        best = min(best, min(costs))
    return DepthFit(scale, shift, best, before)


def _frames_of(view: int, cameras: list[CameraModel], maps: list[np.ndarray | None],
               offsets: np.ndarray) -> Frames:
    """SAMPLE_FRAMES world times every view with depth has: (own map, [(camera, map)])."""
    have = [v for v, m in enumerate(maps) if m is not None]
    lengths = [len(maps[v]) for v in have]  # type: ignore[arg-type]
    lo = max(max(0, -int(offsets[v])) for v in have)
    hi = min(n - max(0, int(offsets[v])) for v, n in zip(have, lengths, strict=True))
    times = np.unique(np.linspace(lo, hi - 1, SAMPLE_FRAMES).round().astype(int))
    out: Frames = []
    for t in times:
        own = maps[view][t + int(offsets[view])]  # type: ignore[index]
        others = [(cameras[v], maps[v][t + int(offsets[v])])  # type: ignore[index]
                  for v in have if v != view]
        out.append((own, others))
    return out


def fit_depth(cameras: list[CameraModel], depth: list[np.ndarray | None],
              offsets: np.ndarray, passes: int = 2) -> list[DepthFit | None]:
    """Per view, its depth scale and shift against the other views (None without depth).

    Args:
        cameras: V views as (re)calibrated. depth: V maps (F, H, W) uint16 mm or None.
        offsets: (V,) whole-frame time offsets. passes: the second pass judges each view
            against the others' maps corrected by the first pass's estimates.
    """
    fits: list[DepthFit | None] = [None] * len(cameras)
    if sum(m is not None for m in depth) < 2:
        return fits
    maps = list(depth)
    for _ in range(passes):
        fits = [None if maps[v] is None else
                _search(camera, _frames_of(v, cameras, maps, offsets), _grid(camera))
                for v, camera in enumerate(cameras)]
        maps = [None if m is None or f is None else correct_depth(m, f.scale, f.shift_px)
                for m, f in zip(depth, fits, strict=True)]
    return fits


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
