"""Whole-frame time offsets of views, from their tracks against the other views' points.

For view ``c`` and a candidate offset ``k``, the points triangulated from the other views at
world time ``t`` are projected into ``c`` and compared with its labels at frame ``t + k``; the
offset with the lowest robust reprojection cost wins. Conventions in :mod:`worker.rig.common`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.rig.common import leave_one_out_points, observed, reprojection_px, shift_frames

# Errors are capped here (px) in the cost, so a few wrong labels cannot decide the offset.
CAP_PX = 30.0
# A non-zero offset must lower the cost by this factor against offset 0: on a clean rig the
# best wrong offset costs 1.5-4x offset 0 (measured on synthetic captures, careful crowd), and
# a frame late costs about 2x as much as on time while the hand moves.
OFFSET_GAIN = 0.75


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


def estimate_time_offsets(cameras: list[CameraModel], keypoints: np.ndarray,
                          visible: np.ndarray, max_offset: int = 2,
                          fixed: tuple[int, ...] = (0,)) -> list[TimeOffset]:
    """Per view, the whole-frame offset in ``-max_offset..max_offset`` that best explains its
    tracks (V, F, P, 2) px against the points of the other views; views in ``fixed`` keep 0.

    A non-zero offset is taken only where its cost is below OFFSET_GAIN x the cost at 0.
    """
    pixels = observed(keypoints, visible)
    candidates = np.arange(-max_offset, max_offset + 1)
    out = []
    for view, camera in enumerate(cameras):
        points = leave_one_out_points(cameras, pixels, view)
        cost, samples = _offset_costs(camera, points, pixels[view], candidates)
        best = 0
        if view not in fixed and np.isfinite(cost).all():
            k = int(candidates[int(np.argmin(cost))])
            if cost.min() < OFFSET_GAIN * cost[candidates == 0][0]:
                best = k
        out.append(TimeOffset(best, candidates, cost, samples))
    return out
