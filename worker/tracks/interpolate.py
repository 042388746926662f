"""A track's value at every frame, from its keyframes.

This is the twin of frontend/annotate/core/interpolate.js: same rules, same formula, same
messages. Both are checked against tests/fixtures/interpolation_golden.json.

Dense value at frame f:
    before the first keyframe (or no keyframes): unplaced, no position, not visible;
    at a keyframe: that keyframe;
    between keyframes k0 < f < k1: interpolated; visibility of k0; linear position when both have
        one, k0's position when only k0 has one, else none;
    after the last keyframe: the last keyframe's position and visibility, interpolated.

Positions are image pixels (x right, y down); keyframes as worker.tracks.keyframes accepts them.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from worker.tracks.keyframes import as_keyframes

STATE_UNPLACED = 0
STATE_KEYFRAME = 1
STATE_INTERPOLATED = 2
STATE_NAMES: tuple[str, ...] = ("unplaced", "keyframe", "interpolated")


@dataclass(frozen=True)
class DenseTrack:
    """A track's value at every frame.

    values: (F, 3) float64 [x, y, visible] with x, y in image px, NaN where there is no position,
        visible 1.0 or 0.0.
    state: (F,) int8, one of STATE_UNPLACED, STATE_KEYFRAME, STATE_INTERPOLATED.
    """

    values: np.ndarray
    state: np.ndarray

    @property
    def xy(self) -> np.ndarray:
        """(F, 2) image px, NaN where there is no position."""
        return self.values[:, :2]

    @property
    def visible(self) -> np.ndarray:
        """(F,) bool."""
        return self.values[:, 2] > 0.5

    def state_names(self) -> list[str]:
        return [STATE_NAMES[s] for s in self.state]


def dense_track(keyframes: Iterable[Any], num_frames: int) -> DenseTrack:
    """The value of a track at every frame 0..num_frames-1 (see the module docstring).

    Args:
        keyframes: dicts {frame, x, y, visible} or compact [frame, x, y, visible01] lists, image px.
        num_frames: F, the clip length.
    """
    kfs = as_keyframes(keyframes)
    values = np.full((num_frames, 3), np.nan)
    values[:, 2] = 0.0
    state = np.full(num_frames, STATE_UNPLACED, dtype=np.int8)
    if not kfs or num_frames <= 0:
        return DenseTrack(values, state)
    k_frame = np.array([k.frame for k in kfs], dtype=np.float64)
    k_x = np.array([np.nan if k.x is None else k.x for k in kfs])
    k_y = np.array([np.nan if k.y is None else k.y for k in kfs])
    k_vis = np.array([1.0 if k.visible else 0.0 for k in kfs])

    frames = np.arange(num_frames, dtype=np.float64)
    i0 = np.searchsorted(k_frame, frames, side="right") - 1
    placed = i0 >= 0
    i0c = np.clip(i0, 0, len(kfs) - 1)
    i1c = np.clip(i0 + 1, 0, len(kfs) - 1)
    at_key = placed & (k_frame[i0c] == frames)
    has_next = placed & ~at_key & (i0 + 1 < len(kfs))

    x0, y0, x1, y1 = k_x[i0c], k_y[i0c], k_x[i1c], k_y[i1c]
    f0, f1 = k_frame[i0c], k_frame[i1c]
    lerp = has_next & ~np.isnan(x0) & ~np.isnan(x1)
    with np.errstate(invalid="ignore", divide="ignore"):
        # Same formula and operation order as interpolate.js, for bit-identical results.
        t = (frames - f0) / (f1 - f0)
        x_lerp = x0 + (x1 - x0) * t
        y_lerp = y0 + (y1 - y0) * t
    values[placed, 0] = np.where(lerp, x_lerp, x0)[placed]
    values[placed, 1] = np.where(lerp, y_lerp, y0)[placed]
    values[placed, 2] = k_vis[i0c][placed]
    state[placed] = STATE_INTERPOLATED
    state[at_key] = STATE_KEYFRAME
    return DenseTrack(values, state)


def dense_points(tracks: Iterable[tuple[int, Iterable[Any]]], num_frames: int,
                 num_points: int) -> tuple[np.ndarray, np.ndarray]:
    """A task's tracks, given as (point index, keyframes) pairs, at every frame.

    Returns (F, P, 2) image px (NaN where a point has no position) and (F, P) bool visibility;
    points without a track, or with an index outside 0..P-1, stay unplaced.
    """
    xy = np.full((num_frames, num_points, 2), np.nan)
    visible = np.zeros((num_frames, num_points), dtype=bool)
    for point, keyframes in tracks:
        if 0 <= point < num_points:
            dense = dense_track(keyframes, num_frames)
            xy[:, point], visible[:, point] = dense.xy, dense.visible
    return xy, visible
