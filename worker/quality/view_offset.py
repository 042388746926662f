"""A camera's systematic offset, told apart from the errors of the workers who label its view.

A camera whose calibration is off (turned by half a degree, moved by 5 mm) shows every point
a few pixels away from where the other views place it: the same way for every worker, point
and frame of that view. A worker's errors are not like that: noise differs per click, a swap
touches two fingers over a span, a frozen track is off by the motion, which changes from frame
to frame. So per view one low-dimensional map is fitted, robustly, to the pairs (where the
references place a point, where the labels put it) of ALL labels of that view over ALL their
points and frames: a similarity about the principal point,

    observed = c + A (reference - c) + t,    A = [[a, -b], [b, a]]    (4 numbers)

(a camera turned about its axis rotates the image about c, turned about another axis or moved
sideways shifts it, moved along its axis scales it). It is trusted only where it explains the
view: at least MIN_PAIRS pairs, labels of which at least SYSTEMATIC_SHARE of the pairs lie
within INLIER_PX of the map (a careful label's noise; a sloppy, random or frozen label's pairs
mostly do not, and such labels do not shape the map), and an offset of at least MIN_OFFSET_PX
(median over the pairs), far beyond what the fit's own noise gives a sound camera. A trusted
map is then the camera's: the view's labels are taken back through it before they are
scored (``correct``), so the camera's fault is reported as the camera's and never charged to
its workers, and everything else they did wrong stays.

Pixels x right, y down, one view; N pairs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

# Residual (px) of a pair that counts as following the map: 2.5 x a careful label's 2 px
# per-axis noise holds ~96 % of careful clicks; an 8 px sloppy label's ~18 %.
INLIER_PX = 5.0
# A label shapes the map when this share of its pairs follows it.
SYSTEMATIC_SHARE = 0.6
# Pairs a view needs before its map is trusted (a few frames of one hand label).
MIN_PAIRS = 40
# An offset below this (median over the view's pairs, px) is left alone: a sound camera's fit
# stays under ~0.3 px (noise of 2 px over hundreds of pairs), a camera off by 0.2 degrees and
# 2 mm shows 2-4 px at 640x480.
MIN_OFFSET_PX = 1.0
# Larger than this (px) is no calibration fault a correction should hide: a camera off by 0.5
# degrees and 5 mm shows 3-8 px at 640x480 (measured 3.1-7.8 px), while one worker's labels
# all 25 px off (a kept poor suggestion, a consistent misplacement) are the worker's, and
# with one worker per view nothing else tells the two apart. A larger camera fault is the
# rig-health report's to find.
MAX_OFFSET_PX = 15.0
# Cauchy scale of the robust fit, px.
CAUCHY_PX = 3.0
IRLS_STEPS = 12


@dataclass(frozen=True)
class ViewOffset:
    """One view's fitted map. params (4,) a, b, tx, ty (see the module); centre (2,) px;
    offset_px the median shift it makes at the view's pairs; pairs the pairs fitted; labels
    how many labels shaped it (of ``seen``); applied whether it is trusted as the camera's."""

    view: int
    params: np.ndarray
    centre: np.ndarray
    offset_px: float
    pairs: int
    labels: int
    seen: int
    applied: bool

    @property
    def rotation_deg(self) -> float:
        return float(np.degrees(np.arctan2(self.params[1], self.params[0])))

    @property
    def scale(self) -> float:
        return float(np.hypot(self.params[0], self.params[1]))

    def forward(self, xy: np.ndarray) -> np.ndarray:
        """Where the camera shows a point the references place at xy (..., 2) px."""
        return _map(self.params, self.centre, xy)

    def correct(self, xy: np.ndarray) -> np.ndarray:
        """Labels (..., 2) px taken back through the map (the inverse of ``forward``): where
        the camera model places what the labels show. Identity where not applied."""
        if not self.applied:
            return np.asarray(xy, np.float64)
        a, b, tx, ty = self.params
        inv = np.array([[a, b], [-b, a]]) / (a * a + b * b)
        d = np.asarray(xy, np.float64) - self.centre - np.array([tx, ty])
        return self.centre + d @ inv.T

    def summary(self) -> dict[str, float]:
        """The numbers a report keeps: offset (median px), its mean shift dx, dy (px) at the
        pairs' centroid, rotation (deg) and scale."""
        return {"offset_px": round(self.offset_px, 2), "rotation_deg": round(self.rotation_deg, 4),
                "scale": round(self.scale, 5), "dx_px": round(float(self.params[2]), 2),
                "dy_px": round(float(self.params[3]), 2), "pairs": float(self.pairs)}


def _map(params: np.ndarray, centre: np.ndarray, xy: np.ndarray) -> np.ndarray:
    a, b, tx, ty = params
    d = np.asarray(xy, np.float64) - centre
    return centre + d @ np.array([[a, -b], [b, a]]).T + np.array([tx, ty])


def _fit(ref: np.ndarray, obs: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(4,) a, b, tx, ty of the similarity taking ref (N, 2) to obs (N, 2), Cauchy-weighted."""
    d = ref - centre
    rows = np.zeros((2 * len(d), 4))
    rows[0::2] = np.stack([d[:, 0], -d[:, 1], np.ones(len(d)), np.zeros(len(d))], axis=1)
    rows[1::2] = np.stack([d[:, 1], d[:, 0], np.zeros(len(d)), np.ones(len(d))], axis=1)
    target = (obs - centre).reshape(-1)
    params = np.array([1.0, 0.0, 0.0, 0.0])
    for _ in range(IRLS_STEPS):
        r = np.linalg.norm(obs - _map(params, centre, ref), axis=1)
        w = np.repeat(1.0 / (1.0 + (r / CAUCHY_PX) ** 2), 2)
        params = np.linalg.lstsq(rows * w[:, None], target * w, rcond=None)[0]
    return params


def fit_view_offset(view: int, pairs: Sequence[tuple[np.ndarray, np.ndarray]],
                    centre: np.ndarray) -> ViewOffset:
    """The view's map from each label's pairs.

    Args:
        view: the view's index. pairs: per label of the view, (reference (N, 2), observed
            (N, 2)) px, finite rows only counted. centre: (2,) px, the principal point.

    Returns:
        ViewOffset; applied only where the module's conditions hold.
    """
    centre = np.asarray(centre, np.float64)
    clean = []
    for ref, obs in pairs:
        ref, obs = np.asarray(ref, np.float64).reshape(-1, 2), np.asarray(obs, np.float64)
        ok = np.isfinite(ref).all(axis=1) & np.isfinite(obs.reshape(-1, 2)).all(axis=1)
        clean.append((ref[ok], obs.reshape(-1, 2)[ok]))
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    params, shaping = identity, [c for c in clean if len(c[0])]
    # Twice: all labels first, then only those that follow the map (several per view).
    for _ in range(2):
        if sum(len(r) for r, _ in shaping) < MIN_PAIRS:
            break
        params = _fit(np.concatenate([r for r, _ in shaping]),
                      np.concatenate([o for _, o in shaping]), centre)
        shaping = [(r, o) for r, o in clean if len(r) and _share(params, centre, r, o)
                   >= SYSTEMATIC_SHARE]
    count = sum(len(r) for r, _ in shaping)
    if count < MIN_PAIRS or not shaping:
        return ViewOffset(view, identity, centre, 0.0, count, len(shaping), len(clean), False)
    params = _fit(np.concatenate([r for r, _ in shaping]),
                  np.concatenate([o for _, o in shaping]), centre)
    ref = np.concatenate([r for r, _ in shaping])
    offset = float(np.median(np.linalg.norm(_map(params, centre, ref) - ref, axis=1)))
    applied = MIN_OFFSET_PX <= offset <= MAX_OFFSET_PX
    return ViewOffset(view, params if applied else identity, centre, offset, count,
                      len(shaping), len(clean), applied)


def _share(params: np.ndarray, centre: np.ndarray, ref: np.ndarray, obs: np.ndarray) -> float:
    """Share of a label's pairs within INLIER_PX of the map."""
    r = np.linalg.norm(obs - _map(params, centre, ref), axis=1)
    return float((r < INLIER_PX).mean())


# A camera out of step by more than this many frames is no sync fault a correction should hide.
MAX_LAG_FRAMES = 1
def shift_frames(values: np.ndarray, lag: int) -> np.ndarray:
    """(F, ...) values of a view whose frame f shows frame f + lag, re-indexed to the frames
    they show: out[f + lag] = values[f]; frames nothing moves into keep their own values."""
    out = np.array(values, copy=True)
    frames = len(out)
    if lag > 0:
        out[lag:] = values[:frames - lag]
    elif lag < 0:
        out[:frames + lag] = values[-lag:]
    return out


def vacated_frames(frames: int, lag: int) -> np.ndarray:
    """(F,) bool: the frames ``shift_frames`` leaves without a value of their own."""
    out = np.zeros(frames, bool)
    if lag > 0:
        out[:lag] = True
    elif lag < 0:
        out[frames + lag:] = True
    return out
