"""Approve, review or reject an assignment from its QC metrics, with reasons and worker feedback.

Thresholds are learned from the population of a project's assignments (median + k * 1.4826 *
MAD: a robust z-score of k, unmoved by a minority of bad workers) and clamped into bounds set by
people (MetricBound): the lower bound keeps a very tight population from flagging normal noise,
the upper bound keeps a bad population from excusing itself. Metrics where low is bad (motion
ratio, completeness, working time) use median - k * 1.4826 * MAD, clamped the same way.

Threshold keys read "<metric>.<review|reject>_<above|below>", so a stored thresholds dict says
by itself which way each one cuts.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Literal

import numpy as np

from worker.quality.bounds import METRIC_BOUNDS, MetricBound
from worker.quality.feedback import (
    checks_reason,
    decided_nothing,
    feedback,
)
from worker.quality.metrics import AssignmentQC

# The consistent estimator of a normal distribution's sigma from the MAD.
MAD_TO_SIGMA = 1.4826
# A label whose worker decided less than this share of its shown positions is mostly
# pre-filled. Its own positions are then the corrections of suggestions, made where the other
# views' consensus (which the suggestions come from) was off, and its own visibility marks
# where the depth rule (which suggested them) disagrees: errors, motion and visibility measured
# on that handful are biased against the worker by selection. Such a label is judged by its
# check suggestions, its swaps and gross errors of its own positions (reject-level median and
# 90th-percentile error); the other metrics are reported, not held against it, and are left
# out of the population the thresholds are learned from.
MOSTLY_PREFILLED_FRACTION = 0.5
# Metrics kept for a mostly pre-filled label, at reject level only.
PREFILLED_GROSS_METRICS = ("median_error_px", "p90_error_px")
# Metrics that hold whatever the label's provenance.
PROVENANCE_FREE_METRICS = ("checks_accepted", "completeness", "working_time_s")


@dataclass
class QCThresholds:
    """Settings of the decision.

    k_review, k_reject: robust z-scores of the review and reject thresholds.
    min_population: fewer assignments with a metric than this, and its threshold is the
        strict end of its bounds (a new project reviews more rather than approve blindly).
    motion_ratio_high: path length above this multiple of the hand's is noise (random clicks).
    landmark_min_separation_mm: two landmarks of one object anchored closer than this on its
        surface mark one spot (reject; worker.quality.landmark_points). 15 mm spans 9-13 px
        at 0.7-1 m in a 640x480 view (f ~ 615 px): three to four times the page's 3 px "one
        spot" radius and several times a careful click's error on the surface (2 px, 2-3 mm),
        while the smallest YCB objects (a marker 2 cm thick, a tuna can 3.3 cm tall) still
        show two points that far apart.
    bounds: MetricBound per metric (see worker.quality.bounds).
    """

    k_review: float = 3.0
    k_reject: float = 6.0
    min_population: int = 8
    motion_ratio_high: float = 3.0
    landmark_min_separation_mm: float = 15.0
    bounds: dict[str, MetricBound] = field(default_factory=lambda: dict(METRIC_BOUNDS))


Outcome = Literal["approve", "review", "reject"]


@dataclass
class Decision:
    outcome: Outcome
    reasons: list[str]
    feedback: str
    provisional: bool

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def _learned(values: np.ndarray, k: float, worse: str) -> float:
    median = float(np.median(values))
    spread = MAD_TO_SIGMA * float(np.median(np.abs(values - median)))
    return median + k * spread if worse == "above" else median - k * spread


def learn_thresholds(metric_rows: list[dict[str, float | None]],
                     bounds: QCThresholds | None = None) -> dict[str, float]:
    """Review and reject thresholds from a population of assignments' metrics.

    Args:
        metric_rows: AssignmentQC.metrics of the project's assignments (None entries skipped).
        bounds: k factors and per-metric bounds; QCThresholds() when None.

    Returns:
        {"<metric>.review_above": x, "<metric>.reject_above": y, ...} (or ..._below), each the
        learned value clamped into its bounds, plus the fixed "motion_ratio.review_above" and
        "landmark_separation_mm.reject_below" (a rule of the task, not of the population: a
        crowd that puts both landmarks on one spot does not make one spot right).
    """
    bounds = bounds if bounds is not None else QCThresholds()
    metric_rows = [r for r in metric_rows if not mostly_prefilled(r)]
    out: dict[str, float] = {}
    for name, rule in bounds.bounds.items():
        values = np.array([r[name] for r in metric_rows if r.get(name) is not None], float)
        enough = values.size >= bounds.min_population
        for level, k, limits in (("review", bounds.k_review, rule.review),
                                 ("reject", bounds.k_reject, rule.reject)):
            if limits is None:
                continue
            lo, hi = limits
            strict = lo if rule.worse == "above" else hi
            value = _learned(values, k, rule.worse) if enough else strict
            out[f"{name}.{level}_{rule.worse}"] = float(min(max(value, lo), hi))
    out["motion_ratio.review_above"] = bounds.motion_ratio_high
    out["landmark_separation_mm.reject_below"] = bounds.landmark_min_separation_mm
    return out


def mostly_prefilled(metrics: dict[str, float | None]) -> bool:
    """Whether the worker decided less than MOSTLY_PREFILLED_FRACTION of the label's shown
    positions (the rest are pre-fill suggestions kept unchanged)."""
    share = metrics.get("decided_fraction")
    return share is not None and share < MOSTLY_PREFILLED_FRACTION


def _failures(metrics: dict[str, float | None], thresholds: dict[str, float]) -> list[tuple]:
    """(level, metric, value, threshold, worse) of every crossed threshold; for a mostly
    pre-filled label only those that hold for it (MOSTLY_PREFILLED_FRACTION)."""
    found = []
    prefilled = mostly_prefilled(metrics)
    for key, limit in thresholds.items():
        name, rule = key.split(".", 1)
        level, worse = rule.split("_")
        if prefilled and name not in PROVENANCE_FREE_METRICS and not (
                name in PREFILLED_GROSS_METRICS and level == "reject"):
            continue
        value = metrics.get(name)
        if value is None:
            continue
        if (worse == "above" and value > limit) or (worse == "below" and value < limit):
            found.append((level, name, value, limit, worse))
    return found


def decide(qc: AssignmentQC, thresholds: dict[str, float], point_names: list[str]) -> Decision:
    """The outcome of one assignment.

    reject: a clear fail (a reject threshold crossed, among them two check suggestions kept
    unchanged, or a swap of fingers); review: a review threshold crossed, nothing decided by
    the worker (every position a suggestion kept unchanged), or a reject-level fail on a
    provisional report (never auto-rejected); approve otherwise.
    reasons are short and technical (for admins); feedback speaks to the worker and names the
    joints, frames and distances.
    """
    failures = _failures(qc.metrics, thresholds)
    swaps = [s for s in qc.swaps if s.get("kind") in ("swap", "mirror")]
    reasons = [f"{'swap' if s['kind'] == 'swap' else 'mirrored fingers'}: {s['message']}"
               for s in swaps]
    worst: dict[str, tuple] = {}
    for fail in sorted(failures, key=lambda f: f[0] != "reject"):
        worst.setdefault(fail[1], fail)
    for level, name, value, limit, worse in worst.values():
        sign = ">" if worse == "above" else "<"
        reasons.append(checks_reason(qc.metrics, level) if name == "checks_accepted"
                       else f"{name} {value:.3g} {sign} {limit:.3g} ({level})")
    undecided = decided_nothing(qc.metrics)
    if undecided:
        reasons.append("decided nothing: every position came from suggestions unchanged")
    elif mostly_prefilled(qc.metrics):
        share = qc.metrics.get("decided_fraction") or 0.0
        reasons.append(f"mostly pre-filled ({share:.0%} of positions the worker's own): judged "
                       "by its check suggestions, swaps and gross errors")
    clear_fail = bool(swaps) or any(f[0] == "reject" for f in worst.values())
    outcome: Outcome
    if clear_fail and not qc.provisional:
        outcome = "reject"
    elif clear_fail or worst or undecided:
        outcome = "review"
    else:
        outcome = "approve"
    if qc.provisional:
        reasons.append("provisional: fewer than 3 camera views to compare with")
    return Decision(outcome=outcome, reasons=reasons, provisional=qc.provisional,
                    feedback=feedback(qc, swaps, worst, thresholds, point_names, outcome))


