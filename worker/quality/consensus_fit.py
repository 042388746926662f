"""The robust multi-view fit behind a hand target's consensus (worker.quality.consensus): each
label's reliability, hypotheses from view pairs, the Cauchy-weighted refinement, leave-one-out
residuals and each reference's spread; and the options that steer it.

Points N = F * P (frames x points), labels L; pixels x right, y down; world metres.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from worker.assist.visibility import HIDDEN_MARGIN_M, SURFACE_MARGIN_M
from worker.geometry.cameras import CameraModel
from worker.geometry.refine import (
    CameraStack,
    cauchy_weights,
    refine_points,
    reprojection_errors,
)
from worker.geometry.triangulate import (
    column_pairs,
    leave_one_out_residuals,
    triangulate_points,
)
from worker.quality.support import reference_spread
from worker.quality.view_labels import ViewLabels, observations

# Rayleigh median / sigma: the median pixel distance of isotropic 2-D noise with per-axis sigma.
_RAYLEIGH_MEDIAN = float(np.sqrt(2.0 * np.log(2.0)))


@dataclass
class HandOptions:
    """Settings of score_hand (all keyword options of score_hand).

    outlier_px: reprojection error above which an observation is an outlier; 10 px is five
        times the 2 px per-axis noise of a careful annotator at 640x480.
    max_pairs: most view pairs tried as hypotheses per point (bounds the run time).
    reliability_points: points sampled to measure each label's reliability (its inlier rate).
    min_sigma_px: floor of a label's estimated noise in the re-weighting.
    min_vote: floor of a label's vote (its inlier rate) when hypotheses are compared.
    swap_refits: times the consensus is refitted with detected swaps undone (the clearest
        first: a second round judges labels the first one's correction cleared).
    min_reliability: a label whose inlier rate is below this does not count as one of the two
        other views a verdict needs (a spammer's or a frozen track's chance agreement).
    suspect_vote: factor on the vote of a label found swapping when the consensus is refitted.
    cauchy_k: the robust refinement's Cauchy scale, in multiples of each label's own noise.
    label_sigma_px: per-axis noise of a careful label (2 px at 640x480, keyframes and
        interpolation included: what the simulated careful annotator measures against the
        truth); errors are normalised to it through the reference's spread (support.py).
    surface_margin_m, hidden_margin_m: depth margins of the visibility check (see metrics).
    unreferenced: keys of labels their own evidence discredits (worker.quality.stretch_qc
        .discredited): each is judged like any other, but enters no consensus and witnesses
        no motion, so it never judges the others.
    """

    outlier_px: float = 10.0
    max_pairs: int = 64
    reliability_points: int = 48
    min_sigma_px: float = 1.0
    min_vote: float = 0.05
    swap_refits: int = 2
    suspect_vote: float = 0.25
    min_reliability: float = 0.5
    cauchy_k: float = 2.5
    label_sigma_px: float = 2.0
    surface_margin_m: float = SURFACE_MARGIN_M
    hidden_margin_m: float = HIDDEN_MARGIN_M
    unreferenced: frozenset[str] = frozenset()

    @classmethod
    def of(cls, options: dict[str, Any]) -> HandOptions:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise ValueError(f"unknown option(s) {', '.join(unknown)}; known: {sorted(known)}")
        return cls(**options)


def _label_reliability(cams: list[CameraModel], pixels: np.ndarray,
                       opts: HandOptions) -> np.ndarray:
    """(L,) fraction of each label's observations that are inliers, on a subsample of points."""
    sample = np.unique(np.linspace(0, len(pixels) - 1, opts.reliability_points).astype(int))
    probe = triangulate_points(cams, pixels[sample], outlier_px=opts.outlier_px, refine=False)
    observed = np.isfinite(pixels[sample]).all(axis=-1).sum(axis=0)
    return probe.inliers.sum(axis=0) / np.maximum(observed, 1)


def _hypothesis_pairs(cams: list[CameraModel], views: np.ndarray, reliability: np.ndarray,
                      opts: HandOptions) -> np.ndarray | None:
    """Column pairs to use as hypotheses: all when few, else pairs among each view's most
    reliable labels, as many as max_pairs allows."""
    stack = CameraStack.of(cams)
    if len(column_pairs(stack)) <= opts.max_pairs:
        return None
    ranked = {v: [c for c in np.argsort(-reliability, kind="stable") if views[c] == v]
              for v in np.unique(views)}
    chosen: list[int] = [r[0] for r in ranked.values()]
    for depth in range(1, max(len(r) for r in ranked.values())):
        more = chosen + [r[depth] for r in ranked.values() if len(r) > depth]
        if len(column_pairs(stack, np.array(more))) > opts.max_pairs:
            break
        chosen = more
    return column_pairs(stack, np.array(sorted(chosen)))


def _label_weights(residuals: np.ndarray, inliers: np.ndarray, min_sigma_px: float) -> np.ndarray:
    """(L,) 1 / sigma^2 per label, sigma from the median leave-one-out distance of its inliers."""
    dist = np.linalg.norm(residuals, axis=-1)
    weights = np.ones(inliers.shape[1])
    for col in range(inliers.shape[1]):
        d = dist[inliers[:, col], col]
        d = d[np.isfinite(d)]
        if d.size:
            sigma = max(float(np.median(d)) / _RAYLEIGH_MEDIAN, min_sigma_px)
            weights[col] = 1.0 / sigma ** 2
    return weights


def distinct_views(inliers: np.ndarray, views: np.ndarray) -> np.ndarray:
    """(N, V') bool: which distinct views have an inlier observation of each point."""
    return np.stack([inliers[:, views == v].any(axis=1) for v in np.unique(views)], axis=1)


@dataclass
class Fit:
    """A consensus fit over N = F * P points and L labels: pixels (N, L, 2) observations,
    points (N, 3) world m, inliers (N, L), loo (N, L, 2) leave-one-out residuals px, spread
    (N, L, 2, 2) px^2 covariance of each leave-one-out reference in the label's view (NaN
    without two other views), views (L,), reliability (L,) inlier rates, weights (L,)
    1 / sigma^2 per label, trusted (L,) the labels that count as a view behind a verdict (by
    their first reliability: a cut vote of a suspected swapper does not change it)."""

    pixels: np.ndarray
    points: np.ndarray
    inliers: np.ndarray
    loo: np.ndarray
    spread: np.ndarray
    views: np.ndarray
    reliability: np.ndarray
    weights: np.ndarray
    trusted: np.ndarray


def _solve(cams: list[CameraModel], pixels: np.ndarray, views: np.ndarray,
           reliability: np.ndarray, opts: HandOptions, weights: np.ndarray | None = None,
           trusted: np.ndarray | None = None
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Robust points, inliers, leave-one-out residuals, their references' spread and label
    weights of ``pixels``."""
    pairs = _hypothesis_pairs(cams, views, reliability, opts)
    # A label's vote counts by its reliability, so that a spammer's point that happens to lie
    # near the epipolar line of a good one cannot outvote a true two-view point; the floor keeps
    # every label able to break a tie.
    votes = np.clip(reliability, opts.min_vote, 1.0)
    tri = triangulate_points(cams, pixels, outlier_px=opts.outlier_px, pairs=pairs, votes=votes)
    if weights is None:
        loo = leave_one_out_residuals(cams, pixels, tri.points, tri.inliers)
        weights = _label_weights(loo, tri.inliers, opts.min_sigma_px)
    stack = CameraStack.of(cams)
    scales = opts.cauchy_k / np.sqrt(weights)
    points = refine_points(stack, pixels, tri.points, tri.inliers, weights, scales)
    errors = reprojection_errors(stack, pixels, points)
    # Inliers the robust fit left far behind (a minority cluster) are inliers no more.
    inliers = tri.inliers & (errors < opts.outlier_px)
    enough = inliers.sum(axis=1) >= 2
    inliers = np.where(enough[:, None], inliers, tri.inliers)
    points = np.where(enough[:, None], points, tri.points)
    errors = reprojection_errors(stack, pixels, points)
    effective = weights * cauchy_weights(np.where(inliers, errors, 0.0), scales)
    loo = leave_one_out_residuals(cams, pixels, points, inliers, effective)
    spread = reference_spread(stack, points, inliers, effective, views,
                              trusted=_trusted(reliability, opts) if trusted is None else trusted)
    return points, inliers, loo, spread, weights


def _trusted(reliability: np.ndarray, opts: HandOptions) -> np.ndarray:
    return np.asarray(reliability >= opts.min_reliability)


def fit_consensus(cameras: list[CameraModel], labels: list[ViewLabels], opts: HandOptions,
         previous: Fit | None = None, reliability: np.ndarray | None = None,
         also: np.ndarray | None = None) -> Fit:
    """The consensus of ``labels``; with ``previous`` (a fit of the same labels before some
    were corrected) only the points whose observations changed, and the rows ``also`` (N,)
    bool, are solved again, with ``reliability`` (L,) if given."""
    cams = [cameras[lab.view] for lab in labels]
    views = np.array([lab.view for lab in labels])
    pixels = observations(labels)
    if previous is None:
        reliability = _label_reliability(cams, pixels, opts)
        points, inliers, loo, spread, weights = _solve(cams, pixels, views, reliability, opts)
        return Fit(pixels, points, inliers, loo, spread, views, reliability, weights,
                    _trusted(reliability, opts))
    same = np.isclose(pixels, previous.pixels, equal_nan=True).all(axis=(1, 2))
    rows = np.flatnonzero(~same | (False if also is None else also))
    fit = Fit(pixels, previous.points.copy(), previous.inliers.copy(), previous.loo.copy(),
               previous.spread.copy(), views,
               previous.reliability if reliability is None else reliability,
               previous.weights if reliability is None
               else previous.weights * np.divide(reliability, previous.reliability,
                                                 out=np.ones(len(reliability)),
                                                 where=previous.reliability > 0),
               previous.trusted)
    if rows.size:
        solved = _solve(cams, pixels[rows], views, fit.reliability, opts, fit.weights,
                        fit.trusted)
        fit.points[rows], fit.inliers[rows], fit.loo[rows], fit.spread[rows] = solved[:4]
    return fit
