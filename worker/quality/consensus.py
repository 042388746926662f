"""Multi-view consensus of a hand target and the quality of every assignment that labelled it.

Each camera view of a sequence is one task; several assignments (workers) may label the same
view. Every visible labelled point is one observation; all observations of a joint in a frame
are triangulated together, robustly (worker.geometry.triangulate), so that a spammer or a
swapper in the pool becomes outliers instead of dragging the consensus:

1. each label's reliability (its inlier rate on a subsample of points) weighs its vote among
   hypotheses, and with many labels only the most reliable ones propose hypotheses;
2. the inliers are refined with a Cauchy loss scaled by each label's own noise (weights
   1 / sigma^2), so a sloppy label weighs less and a minority cluster inside the inlier
   threshold (a swapped finger 10 px away) does not pull the point;
3. each observation is scored against the point fitted without it (leave-one-out), so a label
   is never judged by a consensus it helped to make;
4. where swaps are found, the consensus is refitted once with them undone (or, when the
   consensus itself was swapped by a majority of swappers, with theirs undone) and every label
   is judged again, as it was sent.

Only what a worker decided is an observation: a position pre-filled from the other views'
consensus and kept unchanged (ViewLabels.decided False) enters no fit and is never scored,
so pre-filled views cannot agree with the work they were made from, nor count among the
three views a verdict needs.

Frames F, points P (21 joints, DexYCB order), views V; pixels x right, y down; world metres.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from worker.assist.visibility import (
    HIDDEN_MARGIN_M,
    SURFACE_MARGIN_M,
    DepthMaps,
    SurfaceCheck,
    surface_check,
)
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
from worker.quality.metrics import (
    AssignmentQC,
    completeness,
    depth_visibility,
    error_issues,
    error_summary,
    num,
    per_point_and_frame,
    track_metrics,
)
from worker.quality.motion import (
    TargetMotion,
    expected_shake,
    moved_with,
    others_motion,
    track_jitter,
)
from worker.quality.support import (
    MIN_VIEWS,
    normalised_errors,
    reference_spread,
    spread_px,
)
from worker.quality.swaps import (
    consensus_swapped,
    find_swaps,
    moved_joints,
    overlaps,
    swap_corrections,
    undo_swaps,
)
from worker.quality.view_offset import (
    MAX_LAG_FRAMES,
    ViewOffset,
    fit_view_offset,
    shift_frames,
    vacated_frames,
)
from worker.rig.timing import joint_offsets

# Rayleigh median / sigma: the median pixel distance of isotropic 2-D noise with per-axis sigma.
_RAYLEIGH_MEDIAN = float(np.sqrt(2.0 * np.log(2.0)))


@dataclass
class ViewLabels:
    """One assignment's labels of one view.

    key: the assignment's id. view: index into the cameras list.
    xy: (F, P, 2) image px, NaN where there is no position. visible: (F, P) bool.
    working_time_s: the worker's active time, seconds, if known.
    decided: (F, P) bool, where the position is the worker's own decision (placed, edited or
        a tracking proposal from this view's images accepted); False where it only comes
        from suggestions pre-filled from the other views and left unchanged
        (worker.tracks.sources.decided_mask). None: all of it (work without provenance). Undecided
        positions never enter the consensus and are never scored, so a view pre-filled from
        the others cannot agree with them by construction (leave-one-out holds).
    """

    key: str
    view: int
    xy: np.ndarray
    visible: np.ndarray
    working_time_s: float | None = None
    decided: np.ndarray | None = None


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

    @classmethod
    def of(cls, options: dict[str, Any]) -> HandOptions:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise ValueError(f"unknown option(s) {', '.join(unknown)}; known: {sorted(known)}")
        return cls(**options)


@dataclass
class HandReport:
    """consensus: (F, P, 3) world metres, NaN where unsupported. support: (F, P) number of
    distinct views behind each point. assignments: AssignmentQC per assignment key.
    provisional: fewer than 3 distinct views support the target."""

    consensus: np.ndarray
    support: np.ndarray
    assignments: dict[str, AssignmentQC]
    provisional: bool
    # What a reviewer's replay draws, per assignment key: "reference" (F, P, 2) px where the
    # other views place each point (NaN where they do not fix it), "errors" (F, P) raw px
    # from the label to it (NaN where not scored).
    replay: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    # Per view, its camera's systematic offset (worker.quality.view_offset) and its lag in
    # whole frames: where found, the view's labels were taken back through them before scoring.
    camera_offsets: dict[int, ViewOffset] = field(default_factory=dict)
    camera_lags: dict[int, int] = field(default_factory=dict)

    def to_dict(self) -> dict:
        pts = np.round(self.consensus, 6).astype(object)
        pts[~np.isfinite(self.consensus)] = None
        return {"consensus": pts.tolist(), "support": self.support.astype(int).tolist(),
                "provisional": self.provisional,
                "assignments": {k: a.to_dict() for k, a in self.assignments.items()}}


def check_labels(cameras: list[CameraModel], labels: list[ViewLabels]) -> tuple[int, int]:
    """(F, P) shared by all labels; ValueError naming the field and shape otherwise."""
    if not labels:
        raise ValueError("labels must not be empty")
    frames, points = np.shape(labels[0].xy)[:2]
    keys = set()
    for lab in labels:
        xy, vis = np.shape(lab.xy), np.shape(lab.visible)
        if xy != (frames, points, 2) or vis != (frames, points):
            raise ValueError(f"labels {lab.key!r}: xy must have shape (F={frames}, P={points}, 2) "
                             f"and visible (F, P), got {xy} and {vis}")
        if not 0 <= lab.view < len(cameras):
            raise ValueError(f"labels {lab.key!r}: view {lab.view} is not in 0..{len(cameras) - 1}")
        if lab.decided is not None and np.shape(lab.decided) != (frames, points):
            raise ValueError(f"labels {lab.key!r}: decided must have shape (F={frames}, "
                             f"P={points}), got {np.shape(lab.decided)}")
        if lab.key in keys:
            raise ValueError(f"labels: key {lab.key!r} appears twice")
        keys.add(lab.key)
    return frames, points


def decided_of(lab: ViewLabels) -> np.ndarray:
    """(F, P) bool: where the label's position is the worker's own decision (everywhere for a
    label without provenance)."""
    if lab.decided is None:
        return np.ones(np.shape(lab.visible), bool)
    return np.asarray(lab.decided, bool)


def decided_xy(lab: ViewLabels) -> np.ndarray:
    """(F, P, 2) px of the label's own decisions, NaN where it has none or only suggestions."""
    return np.where(decided_of(lab)[..., None], np.asarray(lab.xy, dtype=np.float64), np.nan)


def _observations(labels: list[ViewLabels]) -> np.ndarray:
    """(F*P, L, 2) px of every label's visible points that the worker decided, NaN elsewhere
    (pre-filled suggestions are the other views' consensus, not an observation of this one)."""
    cols = [np.where(np.asarray(lab.visible, bool)[..., None], decided_xy(lab), np.nan)
            for lab in labels]
    return np.stack(cols, axis=2).reshape(-1, len(labels), 2)


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


def _distinct_views(inliers: np.ndarray, views: np.ndarray) -> np.ndarray:
    """(N, V') bool: which distinct views have an inlier observation of each point."""
    return np.stack([inliers[:, views == v].any(axis=1) for v in np.unique(views)], axis=1)


@dataclass
class _Fit:
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


def _fit(cameras: list[CameraModel], labels: list[ViewLabels], opts: HandOptions,
         previous: _Fit | None = None, reliability: np.ndarray | None = None,
         also: np.ndarray | None = None) -> _Fit:
    """The consensus of ``labels``; with ``previous`` (a fit of the same labels before some
    were corrected) only the points whose observations changed, and the rows ``also`` (N,)
    bool, are solved again, with ``reliability`` (L,) if given."""
    cams = [cameras[lab.view] for lab in labels]
    views = np.array([lab.view for lab in labels])
    pixels = _observations(labels)
    if previous is None:
        reliability = _label_reliability(cams, pixels, opts)
        points, inliers, loo, spread, weights = _solve(cams, pixels, views, reliability, opts)
        return _Fit(pixels, points, inliers, loo, spread, views, reliability, weights,
                    _trusted(reliability, opts))
    same = np.isclose(pixels, previous.pixels, equal_nan=True).all(axis=(1, 2))
    rows = np.flatnonzero(~same | (False if also is None else also))
    fit = _Fit(pixels, previous.points.copy(), previous.inliers.copy(), previous.loo.copy(),
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


@dataclass
class _Judged:
    """One label against its leave-one-out references, (F, P) each unless named: errors px
    normalised to the reference's spread (NaN where not scored: fewer than two other views),
    raw px distances, other_views (distinct views behind the reference), reference (F, P, 2)
    px where the other views place each point, spread (F, P, 2, 2) px^2 its covariance."""

    errors: np.ndarray
    raw: np.ndarray
    other_views: np.ndarray
    reference: np.ndarray
    spread: np.ndarray


# The hand counts as moving when the other labels' joints get this far (median over labels, px)
# from where they were first placed: ten careful clicks' noise.
HAND_MOVES_PX = 20.0
# A label scored on less than this share of its visible points is provisional: the other
# views agree too rarely (or too few views are in) to judge it.
MIN_SCORED_FRACTION = 0.25


def _replay(judged: _Judged) -> dict[str, np.ndarray]:
    """The label's leave-one-out references where two other views fix them (the same rule as
    its errors), and its raw distances to them, px."""
    fixed = np.isfinite(judged.spread).all(axis=(-1, -2))
    return {"reference": np.where(fixed[..., None], judged.reference, np.nan),
            "errors": np.where(np.isfinite(judged.errors), judged.raw, np.nan)}


def _issues(judged: _Judged, outlier_px: float) -> list[dict]:
    """Spans where a point is far off by the normalised error, told in raw pixels."""
    issues = error_issues(judged.errors, outlier_px, judged.other_views)
    for issue in issues:
        first, last = issue["frames"]
        span = judged.raw[first:last + 1, issue["point"]]
        span = span[np.isfinite(judged.errors[first:last + 1, issue["point"]]) & np.isfinite(span)]
        if span.size:
            issue["error_px"] = num(np.median(span), 1)
    return issues


def _assess(lab: ViewLabels, camera: CameraModel, consensus: np.ndarray, judged: _Judged,
            surface: SurfaceCheck | None, motion: TargetMotion | None,
            opts: HandOptions) -> AssignmentQC:
    """Metrics of one label. consensus (F, P, 3) world m; judged: the label against its
    leave-one-out references; surface: the view's depth map looked up at the consensus (None
    without depth); motion: the hand's motion as the other labels' own tracks show it.

    Every metric of positions or visibility reads only the worker's own decisions
    (ViewLabels.decided); completeness and visible_fraction read the whole label."""
    decided = decided_of(lab)
    sent_xy = np.asarray(lab.xy, dtype=np.float64)
    xy = decided_xy(lab)
    visible = np.asarray(lab.visible, bool)
    errors = judged.errors
    # Motion and jitter are measured only where two other trusted views fix the point without
    # this label (support.MIN_OTHER_VIEWS).
    fixed = np.isfinite(judged.spread).all(axis=(-1, -2))
    judged_reference = np.where(fixed[..., None], camera.project(consensus), np.nan)
    scored = np.isfinite(errors)
    metrics = error_summary(errors)
    metrics["outlier_fraction"] = num((errors[scored] > opts.outlier_px).mean()) \
        if scored.any() else None
    metrics["raw_median_error_px"] = num(np.median(judged.raw[scored])) if scored.any() else None
    spread = spread_px(judged.spread)
    metrics["reference_spread_px"] = num(np.median(spread[scored])) if scored.any() else None
    vis_metrics = dict.fromkeys(("visibility_disagreement", "occluded_on_surface",
                                 "visible_behind_surface"))
    if surface is not None:
        # A pre-filled visibility was suggested from this very depth map: no evidence.
        vis_metrics = depth_visibility(visible, SurfaceCheck(surface.on_surface & decided,
                                                             surface.hidden & decided))
    metrics.update(vis_metrics)
    metrics.update(track_metrics(xy, visible, judged_reference, lab.working_time_s))
    metrics["completeness"] = completeness(sent_xy, visible)
    metrics["scored_fraction"] = num(scored.mean())
    # Checks of the label's own track, which hold where the views cannot decide.
    shown_xy = np.where(visible[..., None], xy, np.nan)
    metrics["track_jitter_px"] = track_jitter(shown_xy)
    sent = visible & np.isfinite(sent_xy).all(axis=-1)
    shown = sent & decided
    metrics["decided_fraction"] = num(shown.sum() / sent.sum()) if sent.any() else None
    # Too little of the worker's own work scored: the views cannot judge it (yet). A label
    # whose every shown position is a suggestion has nothing to wait for (decide.py).
    provisional = bool(scored.sum() / max(int(shown.sum()), 1) < MIN_SCORED_FRACTION) \
        if shown.any() or not sent.any() else False
    # Where the views cannot decide, the track against the other views' own tracks: the
    # same clip's motion shakes every view's track alike (scaled by how far the hand travels
    # in each view), what is left over is the worker's hand. (Where a consensus judges the
    # label, its errors and jitter_px say more.)
    own, expected = track_jitter(xy), expected_shake(xy, motion)
    metrics["track_jitter_ratio"] = num(own / expected) if provisional and own \
        is not None and expected else None
    metrics["moved_with_hand"] = moved_with(xy, motion, HAND_MOVES_PX) \
        if motion is not None else None
    per_joint, per_frame = per_point_and_frame(errors)
    swaps = find_swaps(xy, visible & decided, judged.reference, judged.spread,
                       opts.label_sigma_px) if xy.shape[1] == 21 else []
    return AssignmentQC(key=lab.key, view=lab.view, metrics=metrics, per_joint=per_joint,
                        per_frame=per_frame, swaps=swaps, issues=_issues(judged, opts.outlier_px),
                        provisional=provisional)


def score_hand(cameras: list[CameraModel], labels: list[ViewLabels],
               depth: Mapping[int, DepthMaps] | None = None, **options: Any) -> HandReport:
    """Consensus of a hand target from all its labels, and every assignment's quality.

    Args:
        cameras: one CameraModel per view (labels refer to them by index).
        labels: every assignment's ViewLabels of this target (several per view allowed).
        depth: optional {view: (F, H, W) uint16 depth, millimetres, 0 = none} for the
            visibility check.
        options: HandOptions fields (outlier_px, max_pairs, ...).

    Returns:
        HandReport with consensus (F, P, 3) world metres, support (F, P) distinct views,
        assignments {key: AssignmentQC}, provisional (fewer than 3 distinct views support it).
    """
    opts = HandOptions.of(options)
    frames, _ = check_labels(cameras, labels)
    for view, dm in (depth or {}).items():
        if len(np.shape(dm)) != 3 or np.shape(dm)[0] != frames:
            raise ValueError(f"depth[{view}] must have shape (F={frames}, H, W), "
                             f"got {np.shape(dm)}")
    report, fit = _score(cameras, labels, labels, depth, opts)
    # A camera whose calibration is off shows all its labels the same few pixels away: that
    # is the camera's, taken out before anyone is scored (worker.quality.view_offset).
    offsets, lags = _camera_offsets(cameras, labels, fit, frames)
    if any(o.applied for o in offsets.values()) or any(lags.values()):
        sent, first = labels, fit
        labels = [_offset_corrected(lab, offsets[lab.view], lags[lab.view]) for lab in sent]
        report, fit = _score(cameras, labels, labels, depth, opts)
        # Each view's map was fitted against references from other views still off by their
        # own faults (with all but one camera off, a view's references carry most of the
        # others' errors); fitted again, from the labels as sent, against the references of
        # the corrected views, it is the camera's own.
        again = _camera_offsets(cameras, sent, first, frames, lags, fit)[0]
        if any(o.applied for o in again.values()):
            offsets = {view: again[view] if o.applied else o for view, o in offsets.items()}
            labels = [_offset_corrected(lab, offsets[lab.view], lags[lab.view])
                      for lab in sent]
            report, fit = _score(cameras, labels, labels, depth, opts)
    for _ in range(opts.swap_refits):
        corrections = swap_corrections(
            {k: a.swaps for k, a in report.assignments.items()}, report.consensus)
        if not any(corrections.values()):
            break
        # Refit with the swaps undone, so that swapped points stop pulling (or, with several
        # swappers, outvoting) the consensus; every label is then judged as it was sent.
        corrections = _resolve_conflicts(cameras, labels, corrections, report, fit, opts)
        fit_labels = [_undone(lab, corrections[lab.key]) for lab in labels]
        reliability, rows = _suspects(report, labels, corrections, fit, opts)
        report, fit = _score(cameras, labels, fit_labels, depth, opts, fit, reliability, rows)
    _report_offsets(report, offsets, lags)
    return report


def _camera_offsets(cameras: list[CameraModel], labels: list[ViewLabels], fit: _Fit,
                    frames: int, lags: dict[int, int] | None = None,
                    corrected: _Fit | None = None
                    ) -> tuple[dict[int, ViewOffset], dict[int, int]]:
    """Per view, its lag (whole frames) and the map fitted to (leave-one-out reference,
    observation) of every label of the view over every point it is judged on (two other
    views fix it), the label shifted by the lag.

    fit: the labels as sent (``fit.pixels`` their observations). lags: given, they are
    taken as found. corrected: the fit of the labels already corrected (shifted by ``lags``
    and taken back through a first map): the references are then its leave-one-out ones
    (which the view's own correction does not touch), the observations still those sent."""
    source = fit if corrected is None else corrected
    judged = np.isfinite(source.spread).all(axis=(-1, -2)) & np.isfinite(source.loo).all(axis=-1)
    pairs: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    for col, lab in enumerate(labels):
        if corrected is None:
            obs = np.where(judged[:, col, None], fit.pixels[:, col], np.nan)
            ref = obs - fit.loo[:, col]
        else:
            ref = np.where(judged[:, col, None], corrected.pixels[:, col] - corrected.loo[:, col],
                           np.nan)
            obs = fit.pixels[:, col]
        pairs.setdefault(lab.view, []).append((ref.reshape(frames, -1, 2),
                                               obs.reshape(frames, -1, 2)))
    if lags is None:
        lags = _view_lags(cameras, labels, frames)
    # The corrected fit's references are already in the frames the view's images show.
    offsets = {view: fit_view_offset(view, [(r, shift_frames(o, lags.get(view, 0)))
                                            for r, o in found], cameras[view].K[:2, 2])
               for view, found in pairs.items()}
    return offsets, lags


# A view's lag is kept where its own cost there is below this share of the cost at 0: looser
# than the rig's (worker.rig.timing.OFFSET_GAIN) because a QC view is often one worker's
# clicks on a short clip, whose noise (2-3 px) is near one frame's motion; on a sound camera
# the wrong lags cost 1.5-4x the right one.
LAG_GAIN = 0.9


def _view_lags(cameras: list[CameraModel], labels: list[ViewLabels],
               frames: int) -> dict[int, int]:
    """Per labelled view, the whole frames (|k| <= MAX_LAG_FRAMES) by which its images are out
    of step (a camera one frame late: -1), chosen for all views together (worker.rig.timing)
    with the lowest labelled view's time held: judged one view at a time against the others,
    two late views of four split the references two against two and the sound ones look
    early. Each view's observation is the median of its labels' decided visible positions."""
    views = sorted({lab.view for lab in labels})
    if len(views) < 3:
        return dict.fromkeys(views, 0)
    pixels = np.full((len(views), frames, labels[0].xy.shape[1], 2), np.nan)
    for i, view in enumerate(views):
        own = [np.where((lab.visible & decided_of(lab))[..., None], lab.xy, np.nan)
               for lab in labels if lab.view == view]
        with np.errstate(all="ignore"):
            pixels[i] = np.nanmedian(np.stack(own), axis=0) if len(own) > 1 else own[0]
    found = joint_offsets([cameras[v] for v in views], pixels, MAX_LAG_FRAMES, fixed=(0,),
                          gain=LAG_GAIN)
    # A late camera (offset k = 1: its frame f shows world time f - 1) has lag -1.
    return {view: -int(k) for view, k in zip(views, found, strict=True)}


def _offset_corrected(lab: ViewLabels, offset: ViewOffset, lag: int) -> ViewLabels:
    """The label re-indexed to the frames its images show and taken back through the map;
    frames left without a position of their own are not the worker's decision there."""
    xy, visible = shift_frames(lab.xy, lag), shift_frames(lab.visible, lag)
    decided = shift_frames(decided_of(lab), lag) & ~vacated_frames(len(xy), lag)[:, None] \
        if lag else lab.decided
    return ViewLabels(lab.key, lab.view, offset.correct(xy), visible, lab.working_time_s,
                      decided)


def _report_offsets(report: HandReport, offsets: dict[int, ViewOffset],
                    lags: dict[int, int]) -> None:
    """The camera offsets and lags on the report, each one found in its labels' metrics, and
    the replay's references taken back to the view's own pixels and frames."""
    report.camera_offsets, report.camera_lags = offsets, lags
    for key, qc in report.assignments.items():
        offset, lag = offsets.get(qc.view), lags.get(qc.view, 0)
        if lag:
            qc.metrics["camera_lag_frames"] = float(lag)
        if offset is not None and offset.applied:
            qc.metrics["camera_offset_px"] = num(offset.offset_px, 2)
        if key in report.replay and offset is not None:
            replay = report.replay[key]
            replay["reference"] = shift_frames(offset.forward(replay["reference"]), -lag)
            replay["errors"] = shift_frames(replay["errors"], -lag)


def _own_swaps(report: HandReport, corrections: dict[str, list[dict]]) -> list[tuple[str, dict]]:
    """(label key, swap) of every correction that undoes the label's own detected swap (not
    one the consensus made)."""
    return [(key, s) for key, found in corrections.items() for s in found
            if any(overlaps(s, t) for t in report.assignments[key].swaps)]


def _conflicts(items: list[tuple[str, dict]]) -> list[list[tuple[str, dict]]]:
    """Groups of swaps of the same fingers over overlapping frames from different labels."""
    groups: list[list[tuple[str, dict]]] = []
    for item in items:
        joined = [g for g in groups if any(overlaps(item[1], other) for _, other in g)]
        merged = [item] + [x for g in joined for x in g]
        groups = [g for g in groups if g not in joined] + [merged]
    return [g for g in groups if len({key for key, _ in g}) > 1]


def _resolve_conflicts(cameras: list[CameraModel], labels: list[ViewLabels],
                       corrections: dict[str, list[dict]], report: HandReport, fit: _Fit,
                       opts: HandOptions) -> dict[str, list[dict]]:
    """Where labels accuse each other of the same swap over overlapping frames, keep the
    explanation that makes the views agree best.

    With few views a careful label's reference may be made from a swapper and one other view;
    it then looks swapped too; where the swappers outnumber them, careful labels are the
    accused. Each accused label alone, all of them together (several swappers), and every
    other label instead (the accused were right) are undone in turn; the consensus of the
    affected points is refitted, and the choice with the least robust reprojection cost over
    every label wins, among those whose palm is not exchanged over the span
    (consensus_swapped) where there are any.
    """
    groups = _conflicts(_own_swaps(report, corrections))
    if not groups:
        return corrections
    for group in groups:
        rows = np.zeros(report.consensus.shape[:2], bool)
        frames = [min(s["frames"][0] for _, s in group), max(s["frames"][1] for _, s in group)]
        rows[frames[0]:frames[1] + 1, moved_joints([s for _, s in group])] = True
        flat = np.flatnonzero(rows.ravel())
        span = {"kind": group[0][1]["kind"], "fingers": group[0][1]["fingers"],
                "frames": frames}
        accused = {key for key, _ in group}
        # Each accused label alone, all of them, or none of them but everyone else (the
        # consensus was the swappers' and the accused were right).
        choices = [_trial(corrections, group, [item]) for item in group]
        choices.append(_trial(corrections, group, group))
        flipped = _trial(corrections, group, [])
        choices.append({key: found + ([] if key in accused or any(overlaps(span, t)
                                                                    for t in found) else [span])
                        for key, found in flipped.items()})
        costs = []
        for trial in choices:
            trial_fit = _fit(cameras, [_undone(lab, trial[lab.key]) for lab in labels], opts,
                             fit, also=rows.ravel())
            # An explanation that leaves the palm exchanged over the span is the swappers'
            # (two against two ties on the reprojection cost alone).
            palm = consensus_swapped(trial_fit.points.reshape(report.consensus.shape), span)
            costs.append((palm, _robust_cost(cameras, labels, trial_fit, flat, opts.outlier_px)))
        corrections = choices[min(range(len(choices)), key=lambda i: costs[i])]
    return corrections


def _trial(corrections: dict[str, list[dict]], group: list[tuple[str, dict]],
           chosen: list[tuple[str, dict]]) -> dict[str, list[dict]]:
    """``corrections`` with, of the conflicting ``group``, only the ``chosen`` swaps undone."""
    return {key: [s for s in found if (key, s) not in group or (key, s) in chosen]
            for key, found in corrections.items()}


def _robust_cost(cameras: list[CameraModel], labels: list[ViewLabels], fit: _Fit,
                 rows: np.ndarray, cap_px: float) -> float:
    """Sum over the rows' observations of min(error, cap)^2 px^2, each label against the
    fitted points as it entered the fit."""
    stack = CameraStack.of([cameras[lab.view] for lab in labels])
    errors = reprojection_errors(stack, fit.pixels[rows], fit.points[rows])
    capped = np.minimum(np.where(np.isfinite(errors), errors, 0.0), cap_px)
    observed = np.isfinite(fit.pixels[rows]).all(axis=-1)
    # A point the trial could not fit at all costs every observation the cap.
    capped = np.where(np.isfinite(fit.points[rows]).all(axis=1)[:, None], capped, cap_px)
    return float((np.where(observed, capped, 0.0) ** 2).sum())


def _suspects(report: HandReport, labels: list[ViewLabels], corrections: dict[str, list[dict]],
              fit: _Fit, opts: HandOptions) -> tuple[np.ndarray, np.ndarray]:
    """Label reliabilities (L,) with the detected swappers' votes (and weights) cut, and the
    rows (N,) bool
    to solve again: every frame of the joints their swaps move. Where a swapper and one
    careful view are the only two views of a point left, the two hypotheses tie; a swap
    found elsewhere in the clip is what breaks the tie, beyond the span already undone."""
    reliability = fit.reliability.copy()
    swaps: list[dict] = []
    for col, lab in enumerate(labels):
        own = [s for s in corrections[lab.key]
               if any(overlaps(s, t) for t in report.assignments[lab.key].swaps)]
        if own:
            reliability[col] *= opts.suspect_vote
            swaps += own
    rows = np.zeros(report.consensus.shape[:2], bool)
    if swaps:
        rows[:, moved_joints(swaps)] = True
    return reliability, rows.ravel()


def _undone(lab: ViewLabels, swaps: list[dict]) -> ViewLabels:
    if not swaps:
        return lab
    sent_xy = np.asarray(lab.xy, np.float64)
    xy, visible = undo_swaps(sent_xy, np.asarray(lab.visible, bool), swaps)
    # The decisions move with the points they belong to.
    decided = None if lab.decided is None else undo_swaps(sent_xy, decided_of(lab), swaps)[1]
    return ViewLabels(lab.key, lab.view, xy, visible, lab.working_time_s, decided)


def _as_sent(lab: ViewLabels, fitted: ViewLabels, camera: CameraModel, consensus: np.ndarray,
             judged: _Judged, sigma_px: float) -> _Judged:
    """The label as sent where the fit used a corrected copy: plain distances to the consensus
    there (the copy's residuals describe other joints)."""
    sent_xy = np.asarray(lab.xy, np.float64)
    changed = (np.asarray(lab.visible) != np.asarray(fitted.visible)) \
        | ~np.isclose(sent_xy, fitted.xy, equal_nan=True).all(axis=-1)
    reference = camera.project(consensus)
    own = np.asarray(lab.visible, bool) & decided_of(lab)
    offset = np.where(own[..., None], sent_xy - reference, np.nan)
    plain = normalised_errors(offset, judged.spread, sigma_px)
    return _Judged(errors=np.where(changed, plain, judged.errors),
                   raw=np.where(changed, np.linalg.norm(offset, axis=-1), judged.raw),
                   other_views=judged.other_views,
                   reference=np.where(changed[..., None], reference, judged.reference),
                   spread=judged.spread)


def _score(cameras: list[CameraModel], labels: list[ViewLabels], fit_labels: list[ViewLabels],
           depth: Mapping[int, DepthMaps] | None, opts: HandOptions,
           previous: _Fit | None = None, reliability: np.ndarray | None = None,
           also: np.ndarray | None = None) -> tuple[HandReport, _Fit]:
    """Consensus from ``fit_labels`` (updating ``previous`` where given), every label of
    ``labels`` judged against it; the report and the fit."""
    frames, points = np.shape(labels[0].xy)[:2]
    fit = _fit(cameras, fit_labels, opts, previous, reliability, also)
    fitted, inliers, loo, views = fit.points, fit.inliers, fit.loo, fit.views
    consensus = fitted.reshape(frames, points, 3)
    distinct = _distinct_views(inliers, views)
    support = distinct.sum(axis=1)
    view_ids = np.unique(views)
    has_point = np.isfinite(fitted).all(axis=1)
    # The three-views rule for the target: a consensus needs three views behind its points.
    provisional = not has_point.any() or float(np.median(support[has_point])) < MIN_VIEWS
    raw = np.linalg.norm(loo, axis=-1)
    normalised = normalised_errors(loo, fit.spread, opts.label_sigma_px)
    # Where each label's other views place its points: its observation less its residual
    # against the point fitted without it; the consensus where it did not observe the point.
    projected = np.stack([cameras[lab.view].project(fitted) for lab in labels], axis=1)
    observed = np.isfinite(loo).all(axis=-1)
    reference = np.where(observed[..., None], fit.pixels - loo, projected)
    # Each view's depth map is looked up once, at the consensus every label of it is judged by.
    surfaces = {view: surface_check(cameras[view], consensus, dm, opts.surface_margin_m,
                                    opts.hidden_margin_m)
                for view, dm in (depth or {}).items() if view in {lab.view for lab in labels}}
    # Only the workers' own decisions witness the hand's motion (a label of suggestions alone
    # is left out: it would count as a hand that stands still).
    motion = others_motion({lab.key: decided_xy(lab) for lab in labels
                            if decided_of(lab).any() or not np.isfinite(lab.xy).any()})
    assignments = {}
    replay = {}
    for col, lab in enumerate(labels):
        own = distinct[:, np.searchsorted(view_ids, lab.view)]
        judged = _Judged(
            errors=normalised[:, col].reshape(frames, points),
            raw=raw[:, col].reshape(frames, points),
            other_views=(support - own).reshape(frames, points),
            reference=reference[:, col].reshape(frames, points, 2),
            spread=fit.spread[:, col].reshape(frames, points, 2, 2))
        if fit_labels[col] is not lab:
            judged = _as_sent(lab, fit_labels[col], cameras[lab.view], consensus, judged,
                              opts.label_sigma_px)
        qc = _assess(lab, cameras[lab.view], consensus, judged, surfaces.get(lab.view),
                     motion.get(lab.key), opts)
        qc.provisional = qc.provisional or provisional
        assignments[lab.key] = qc
        replay[lab.key] = _replay(judged)
    report = HandReport(consensus=consensus, support=support.reshape(frames, points),
                        assignments=assignments, provisional=provisional, replay=replay)
    return report, fit
