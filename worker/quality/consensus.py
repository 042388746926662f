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

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from worker.assist.visibility import DepthMaps, SurfaceCheck, surface_check
from worker.geometry.cameras import CameraModel
from worker.quality.consensus_fit import Fit, HandOptions, distinct_views, fit_consensus
from worker.quality.hand_report import HandReport
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
from worker.quality.support import MIN_VIEWS, normalised_errors, spread_px
from worker.quality.swap_conflicts import resolve_conflicts, suspects, undone
from worker.quality.swaps import find_swaps, swap_corrections
from worker.quality.view_faults import camera_offsets, offset_corrected, report_offsets
from worker.quality.view_labels import ViewLabels, check_labels, decided_of, decided_xy
from worker.quality.view_offset import ViewOffset


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
    metrics = _error_metrics(judged, opts.outlier_px)
    metrics.update(_visibility_metrics(visible, decided, surface))
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


def _visibility_metrics(visible: np.ndarray, decided: np.ndarray,
                        surface: SurfaceCheck | None) -> dict[str, float | None]:
    """The label's visibility against its view's depth at the consensus (None without depth);
    a pre-filled visibility was suggested from this very depth map: no evidence."""
    if surface is None:
        return dict.fromkeys(("visibility_disagreement", "occluded_on_surface",
                              "visible_behind_surface"))
    return depth_visibility(visible, SurfaceCheck(surface.on_surface & decided,
                                                  surface.hidden & decided))


def _error_metrics(judged: _Judged, outlier_px: float) -> dict[str, float | None]:
    """The label's errors against its references: their summary (normalised), the share
    beyond ``outlier_px``, the raw median and the references' own spread, px."""
    errors = judged.errors
    scored = np.isfinite(errors)
    metrics = error_summary(errors)
    metrics["outlier_fraction"] = num((errors[scored] > outlier_px).mean()) \
        if scored.any() else None
    metrics["raw_median_error_px"] = num(np.median(judged.raw[scored])) if scored.any() else None
    spread = spread_px(judged.spread)
    metrics["reference_spread_px"] = num(np.median(spread[scored])) if scored.any() else None
    return metrics


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
    report, fit, labels, offsets, lags = _without_camera_faults(cameras, labels, depth, opts,
                                                                report, fit)
    for _ in range(opts.swap_refits):
        corrections = swap_corrections(
            {k: a.swaps for k, a in report.assignments.items()}, report.consensus)
        if not any(corrections.values()):
            break
        # Refit with the swaps undone, so that swapped points stop pulling (or, with several
        # swappers, outvoting) the consensus; every label is then judged as it was sent.
        corrections = resolve_conflicts(cameras, labels, corrections, report, fit, opts)
        fit_labels = [undone(lab, corrections[lab.key]) for lab in labels]
        reliability, rows = suspects(report, labels, corrections, fit, opts)
        report, fit = _score(cameras, labels, fit_labels, depth, opts, fit, reliability, rows)
    report_offsets(report, offsets, lags)
    return report


def _without_camera_faults(
    cameras: list[CameraModel], labels: list[ViewLabels], depth: Mapping[int, DepthMaps] | None,
    opts: HandOptions, report: HandReport, fit: Fit,
) -> tuple[HandReport, Fit, list[ViewLabels], dict[int, ViewOffset], dict[int, int]]:
    """The report and fit scored again with each camera's lag and offset taken out of its
    labels (as corrected; the camera offsets and lags found). A camera whose calibration is
    off shows all its labels the same few pixels away: that is the camera's, taken out before
    anyone is scored (worker.quality.view_faults)."""
    frames = len(labels[0].xy)
    offsets, lags = camera_offsets(cameras, labels, fit, frames, silent=opts.unreferenced)
    if not (any(o.applied for o in offsets.values()) or any(lags.values())):
        return report, fit, labels, offsets, lags
    sent, first = labels, fit
    labels = [offset_corrected(lab, offsets[lab.view], lags[lab.view]) for lab in sent]
    report, fit = _score(cameras, labels, labels, depth, opts)
    # Each view's map was fitted against references from other views still off by their own
    # faults (with all but one camera off, a view's references carry most of the others'
    # errors); fitted again, from the labels as sent, against the references of the corrected
    # views, it is the camera's own.
    again = camera_offsets(cameras, sent, first, frames, lags, fit)[0]
    if any(o.applied for o in again.values()):
        offsets = {view: again[view] if o.applied else o for view, o in offsets.items()}
        labels = [offset_corrected(lab, offsets[lab.view], lags[lab.view]) for lab in sent]
        report, fit = _score(cameras, labels, labels, depth, opts)
    return report, fit, labels, offsets, lags


def _as_sent(lab: ViewLabels, fitted: ViewLabels, camera: CameraModel, consensus: np.ndarray,
             judged: _Judged, sigma_px: float) -> _Judged:
    """The label as sent where the fit used a corrected copy: plain distances to the consensus
    there (the copy's residuals describe other joints)."""
    sent_xy = np.asarray(lab.xy, np.float64)
    changed = (np.asarray(lab.visible) != np.asarray(fitted.visible)) \
        | ~np.isclose(sent_xy, fitted.xy, equal_nan=True).all(axis=-1) \
        | (decided_of(lab) != decided_of(fitted))
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
           previous: Fit | None = None, reliability: np.ndarray | None = None,
           also: np.ndarray | None = None) -> tuple[HandReport, Fit]:
    """Consensus from ``fit_labels`` (updating ``previous`` where given), every label of
    ``labels`` judged against it; the report and the fit."""
    frames, points = np.shape(labels[0].xy)[:2]
    fit_labels = [_unreferenced(lab) if lab.key in opts.unreferenced else lab
                  for lab in fit_labels]
    fit = fit_consensus(cameras, fit_labels, opts, previous, reliability, also)
    fitted, inliers, loo, views = fit.points, fit.inliers, fit.loo, fit.views
    consensus = fitted.reshape(frames, points, 3)
    distinct = distinct_views(inliers, views)
    support = distinct.sum(axis=1)
    view_ids = np.unique(views)
    has_point = np.isfinite(fitted).all(axis=1)
    # The three-views rule for the target: a consensus needs three views behind its points.
    provisional = not has_point.any() or float(np.median(support[has_point])) < MIN_VIEWS
    raw = np.linalg.norm(loo, axis=-1)
    normalised = normalised_errors(loo, fit.spread, opts.label_sigma_px)
    reference = _references(cameras, labels, fit)
    # Each view's depth map is looked up once, at the consensus every label of it is judged by.
    surfaces = {view: surface_check(cameras[view], consensus, dm, opts.surface_margin_m,
                                    opts.hidden_margin_m)
                for view, dm in (depth or {}).items() if view in {lab.view for lab in labels}}
    # Only the workers' own decisions witness the hand's motion (a label of suggestions alone
    # is left out: it would count as a hand that stands still).
    motion = others_motion({lab.key: decided_xy(lab) for lab in labels
                            if decided_of(lab).any() or not np.isfinite(lab.xy).any()},
                           silent=opts.unreferenced)
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


def _unreferenced(lab: ViewLabels) -> ViewLabels:
    """The label as the fit sees one its own evidence discredits: no decision of its own
    (it enters no consensus; it is judged as sent, by plain distances, see _as_sent)."""
    return dataclasses.replace(lab, decided=np.zeros(np.shape(lab.visible), bool))


def _references(cameras: list[CameraModel], labels: list[ViewLabels], fit: Fit) -> np.ndarray:
    """(N, L, 2) px: where each label's other views place its points: its observation less its
    residual against the point fitted without it; the consensus where it did not observe the
    point."""
    projected = np.stack([cameras[lab.view].project(fit.points) for lab in labels], axis=1)
    observed = np.isfinite(fit.loo).all(axis=-1)
    return np.where(observed[..., None], fit.pixels - fit.loo, projected)
