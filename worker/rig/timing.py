"""Whole-frame time offsets of views, from their tracks against the other views' points.

The offsets are chosen together, the master's time held: for a set of offsets every view is
re-indexed to world time, the points are triangulated from all views, and the set whose capped
reprojection error over all views is lowest wins. Judging one view at a time against the
others as they are fails where several views are late: at 4 views with 2 late the others
split two against two and the sound views look early. Small rigs try every set; larger ones
descend one view at a time from the per-view answers. Each view's reported costs are its own
candidates against the others aligned by the chosen set. Conventions in
:mod:`worker.rig.common`.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.rig.common import (
    align_views,
    leave_one_out_points,
    observed,
    reprojection_px,
    shift_frames,
    triangulate_views,
)

# Errors are capped here (px) in the cost, so a few wrong labels cannot decide the offset.
CAP_PX = 30.0
# A non-zero offset must lower the cost by this factor against offset 0: on a clean rig the
# best wrong offset costs 1.5-4x offset 0 (measured on synthetic captures, careful crowd), and
# a frame late costs about 2x as much as on time while the hand moves.
OFFSET_GAIN = 0.75
# Rigs with at most this many offset sets are searched whole (4 views, offsets -2..2: 125).
EXHAUSTIVE_SETS = 250


@dataclass(frozen=True)
class TimeOffset:
    """One view's offset: ``frames`` (the chosen k), ``cost_px`` (K,) the robust mean error of
    each candidate in ``candidates`` (K,), ``samples`` the observations compared."""

    frames: int
    candidates: np.ndarray
    cost_px: np.ndarray
    samples: int


def _offset_costs(camera: CameraModel, points: np.ndarray, pixels: np.ndarray,
                  candidates: np.ndarray) -> tuple[np.ndarray, int]:
    """Capped mean reprojection error (px) per candidate over one common set of frames."""
    span = int(np.abs(candidates).max())
    frames = pixels.shape[0]
    common = np.zeros(frames, bool)
    common[span:frames - span] = True
    errs = []
    for k in candidates:
        moved = shift_frames(pixels, int(k))  # moved[t] = pixels[t + k]
        errs.append(reprojection_px(camera, points, moved))
    stacked = np.stack(errs)  # (K, F, P)
    usable = np.isfinite(stacked).all(axis=0) & common[:, None]
    if not usable.any():
        return np.full(len(candidates), np.nan), 0
    capped = np.minimum(stacked[:, usable], CAP_PX)
    return capped.mean(axis=1), int(usable.sum())


def _aligned(pixels: np.ndarray, offsets: tuple[int, ...] | list[int]) -> np.ndarray:
    """Observations (V, F, P, 2) px, NaN where unobserved, re-indexed to world time."""
    return align_views(pixels, np.isfinite(pixels).all(axis=-1), np.asarray(offsets))[0]


def _own_costs(cameras: list[CameraModel], pixels: np.ndarray, offsets: tuple[int, ...],
               views: list[int], candidates: np.ndarray) -> dict[int, tuple[np.ndarray, int]]:
    """Per view of ``views``: its own candidates' costs and samples (_offset_costs), on its
    frames as recorded, against the points of the other views re-indexed by ``offsets``."""
    aligned = _aligned(pixels, offsets)
    return {view: _offset_costs(cameras[view], leave_one_out_points(cameras, aligned, view),
                                pixels[view], candidates) for view in views}


def _joint_cost(cameras: list[CameraModel], pixels: np.ndarray, offsets: tuple[int, ...],
                common: np.ndarray) -> float:
    """Capped mean reprojection error (px) of all views re-indexed by ``offsets``, against the
    points triangulated from all of them, over the world frames ``common`` (F,) bool."""
    aligned = _aligned(pixels, offsets)
    points = triangulate_views(cameras, aligned, list(range(len(cameras))))
    errs = np.stack([reprojection_px(c, points, aligned[v]) for v, c in enumerate(cameras)])
    usable = np.isfinite(errs) & common[None, :, None]
    if not usable.any():
        return float("nan")
    return float(np.minimum(errs[usable], CAP_PX).mean())


def _search(cameras: list[CameraModel], pixels: np.ndarray, start: tuple[int, ...],
            candidates: np.ndarray, fixed: tuple[int, ...]) -> tuple[int, ...]:
    """The offset set of lowest joint cost."""
    span = int(np.abs(candidates).max())
    frames = pixels.shape[1]
    common = np.zeros(frames, bool)
    common[span:frames - span] = True
    free = [v for v in range(len(cameras)) if v not in fixed]
    cache: dict[tuple[int, ...], float] = {}

    def cost(offsets: tuple[int, ...]) -> float:
        if offsets not in cache:
            value = _joint_cost(cameras, pixels, offsets, common)
            cache[offsets] = value if np.isfinite(value) else np.inf
        return cache[offsets]

    if len(candidates) ** len(free) <= EXHAUSTIVE_SETS:
        for combo in itertools.product(candidates.tolist(), repeat=len(free)):
            offsets = [0] * len(cameras)
            for v, k in zip(free, combo, strict=True):
                offsets[v] = int(k)
            cost(tuple(offsets))
        best = min(cache, key=cache.__getitem__)
    else:
        best = start
        improved = True
        while improved:
            improved = False
            for v in free:
                for k in candidates.tolist():
                    trial = best[:v] + (int(k),) + best[v + 1:]
                    if cost(trial) < cost(best):
                        best, improved = trial, True
    return best


def joint_offsets(cameras: list[CameraModel], pixels: np.ndarray, max_offset: int = 2,
                  fixed: tuple[int, ...] = (0,), gain: float = OFFSET_GAIN) -> tuple[int, ...]:
    """Per view, its whole-frame offset in ``-max_offset..max_offset`` (views in ``fixed``
    keep 0), chosen together from observations (V, F, P, 2) px, NaN where unobserved; a
    non-zero offset is kept where the view's own cost there is below ``gain`` x at 0."""
    candidates = np.arange(-max_offset, max_offset + 1)
    zero = (0,) * len(cameras)
    start = list(zero)
    free = [v for v in range(len(cameras)) if v not in fixed]
    for view, (cost, _) in _own_costs(cameras, pixels, zero, free, candidates).items():
        if np.isfinite(cost).all():
            start[view] = int(candidates[int(np.argmin(cost))])
    best = _search(cameras, pixels, tuple(start), candidates, fixed)
    # Each view keeps a non-zero offset only where, against the others in world time, its own
    # cost at that offset is below ``gain`` x its cost at 0 (a joint figure dilutes one late
    # view among many).
    kept = list(best)
    moved = [v for v, k in enumerate(best) if k]
    for view, (cost, _) in _own_costs(cameras, pixels, best, moved, candidates).items():
        if not cost[candidates == best[view]][0] < gain * cost[candidates == 0][0]:
            kept[view] = 0
    return tuple(kept)


def estimate_time_offsets(cameras: list[CameraModel], keypoints: np.ndarray,
                          visible: np.ndarray, max_offset: int = 2,
                          fixed: tuple[int, ...] = (0,)) -> list[TimeOffset]:
    """Per view, the whole-frame offset in ``-max_offset..max_offset`` that best explains its
    tracks (V, F, P, 2) px together with the other views' (joint_offsets); views in ``fixed``
    keep 0."""
    pixels = observed(keypoints, visible)
    candidates = np.arange(-max_offset, max_offset + 1)
    chosen = joint_offsets(cameras, pixels, max_offset, fixed)
    costs = _own_costs(cameras, pixels, chosen, list(range(len(cameras))), candidates)
    return [TimeOffset(int(chosen[view]), candidates, cost, samples)
            for view, (cost, samples) in costs.items()]
