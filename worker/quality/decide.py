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

from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Literal

import numpy as np

from worker.assist.checks import CHECK_OFFSET_PX
from worker.quality.metrics import AssignmentQC
from worker.tracks.spans import format_spans

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


@dataclass(frozen=True)
class MetricBound:
    """How one metric is judged. worse: "above" or "below" the threshold is bad.
    review, reject: (lowest, highest) values the learned threshold may take; reject None: the
    metric alone never rejects."""

    worse: Literal["above", "below"]
    review: tuple[float, float]
    reject: tuple[float, float] | None = None


def _bounds() -> dict[str, MetricBound]:
    # Pixel bounds suit 640x480 views. Hand errors are normalised to how well the other views
    # fix each point (worker.quality.support), so they read the same at 8 views as at 4: a
    # careful annotator (2 px per-axis noise, keyframes interpolated) scores a median of
    # 1.6-1.9 px and a 90th percentile of 3.1-3.6 px; a sloppy one (8 px) 2.9-5.7 and 6.3-10.7
    # (its raw errors, 7-8 px, shrink where the reference itself is loose). Object landmarks
    # are judged against the silhouette. Fractions: careful workers leave ~0 outliers (sloppy
    # ones 25-45%, so they are reviewed, not rejected, on that alone) and mark <2% of the
    # points on the visible surface as occluded.
    return {
        "median_error_px": MetricBound("above", (2.8, 3.5), (12.0, 20.0)),
        "p90_error_px": MetricBound("above", (5.5, 7.0), (30.0, 60.0)),
        "outlier_fraction": MetricBound("above", (0.05, 0.15), (0.5, 0.7)),
        # Hands: against the consensus, whose own shake adds where few views fix it (3.2 px
        # for a careful track at 4 views); the track's own shake is track_jitter_px. Object
        # landmarks: the track's shake beyond the other views' (worker.quality.landmarks).
        "jitter_px": MetricBound("above", (4.0, 6.0)),
        "motion_ratio": MetricBound("below", (0.4, 0.6), (0.1, 0.2)),
        "occluded_on_surface": MetricBound("above", (0.1, 0.2), (0.3, 0.45)),
        "completeness": MetricBound("below", (0.9, 0.95), (0.5, 0.5)),
        "working_time_s": MetricBound("below", (10.0, 30.0)),
        # Object landmarks: a careful track never leaps (0 jumps); a swap of the two makes two.
        "jump_fraction": MetricBound("above", (0.02, 0.05)),
        # Share of the object's travel (as the other views see it) a track follows: views see the
        # motion at different scales (0.4-1 for careful tracks); one frame copied to all: ~0.
        "moved_with_object": MetricBound("below", (0.25, 0.35), (0.08, 0.12)),
        # Object landmarks against the solved object (worker.quality.anchored), 640x480: a
        # careful track follows its anchored surface point within 1.5-2.5 px (median; 90th
        # percentile 3.2-5.7), a sloppy one 5.5-9.5 (12-18); two swapped landmarks put a
        # third of the clip tens of px off (90th percentile 14-120); a careful worker marks
        # up to 21% of the point's visible frames occluded (near the silhouette a point is
        # seen at a grazing angle), the occluder ~60%; a landmark whose
        # ray never meets the object (random clicks) cannot be anchored at all.
        "anchored_median_px": MetricBound("above", (3.5, 4.5), (12.0, 20.0)),
        "anchored_p90_px": MetricBound("above", (8.0, 10.0), (25.0, 40.0)),
        "anchored_visible_occluded": MetricBound("above", (0.3, 0.35), (0.45, 0.5)),
        # Near the hand's edge the depth camera and a careful eye part ways: careful tracks
        # keep up to 0.78 of their few hidden frames visible; this only asks for a look.
        "anchored_hidden_visible": MetricBound("above", (0.85, 0.9)),
        "anchored_drift_px": MetricBound("above", (5.0, 8.0)),
        "anchored_fraction": MetricBound("below", (0.75, 0.75), (0.4, 0.4)),
        # Hands, from the label's own track (they hold where too few views agree to compare).
        # Random clicks shake ~70 px/frame^2 at 30 fps, any real track a few. Against the other
        # views' tracks of the same clip (whose motion shakes them alike): careful tracks
        # 0.6-1.4 times the others' median, sloppy ones 1.7-3.6. A frozen track travels
        # nothing of the hand's motion, careful ones 0.33-1 of it as the other views see it.
        "track_jitter_px": MetricBound("above", (30.0, 30.0), (60.0, 60.0)),
        "track_jitter_ratio": MetricBound("above", (1.55, 1.6)),
        "moved_with_hand": MetricBound("below", (0.15, 0.25), (0.05, 0.1)),
        # Check suggestions (worker.assist.checks) kept unchanged although each was shown
        # CHECK_OFFSET_PX off the point, plain to anyone who looks: one may be a slip among
        # corrected ones (review); two are suggestions accepted without looking (reject).
        # Fixed, whatever the population does: work without suggestions keeps none.
        "checks_accepted": MetricBound("above", (0.0, 0.0), (1.0, 1.0)),
        # Share of a hand track's interpolated stretches its own view's images say the point
        # left (worker.quality.stretch_qc): a careful worker keys where the path bends and
        # leaves 0-12% (the tracker's own slips); one keying every 4th frame through fast
        # motion 70-80%.
        "unfollowed_stretches": MetricBound("above", (0.2, 0.25), (0.45, 0.55)),
    }


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
    bounds: MetricBound per metric (see _bounds).
    """

    k_review: float = 3.0
    k_reject: float = 6.0
    min_population: int = 8
    motion_ratio_high: float = 3.0
    landmark_min_separation_mm: float = 15.0
    bounds: dict[str, MetricBound] = field(default_factory=_bounds)


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


def _pct(value: float) -> str:
    return f"{100.0 * value:.0f}%"


# One sentence per failing metric, for the worker; {v} the value, {t} the threshold.
_ADVICE: dict[str, Callable[[float, float], str]] = {
    "median_error_px": lambda v, t: (f"Half of your points are more than {v:.1f} px off "
                                     f"(aim for under {t:.0f} px)."),
    "p90_error_px": lambda v, t: (f"A tenth of your points are more than {v:.0f} px off; "
                                  "recheck the frames named above."),
    "outlier_fraction": lambda v, t: f"{_pct(v)} of your visible points are far off.",
    "jitter_px": lambda v, t: (f"Your tracks jitter ({v:.1f} px per frame^2); follow each point "
                               "smoothly from keyframe to keyframe."),
    "motion_ratio": lambda v, t: (
        f"Your points move {v:.1f} times as much as the hand: place each point on the joint "
        "it names." if v > 1 else
        f"Your points barely move while the hand moves ({_pct(v)} of its motion): place each "
        "point on every keyframe instead of copying one frame to all."),
    "occluded_on_surface": lambda v, t: (
        f"You marked points occluded in {_pct(v)} of the frames where the depth camera sees them "
        "on the surface; mark a point occluded only while something hides it."),
    "completeness": lambda v, t: (f"Only {_pct(v)} of the points are placed or marked "
                                  "occluded; place every visible point."),
    "working_time_s": lambda v, t: f"You spent only {v:.0f} s on this task.",
    "jump_fraction": lambda v, t: ("Your landmarks jump between frames; keep each one on the "
                                   "same spot of the object all through the clip."),
    "track_jitter_px": lambda v, t: (f"Your points leap from frame to frame ({v:.0f} px per "
                                     "frame^2); place each keyframe on the joint itself."),
    "track_jitter_ratio": lambda v, t: (f"Your points shake {v:.1f} times as much as the other "
                                        "views' from frame to frame; place each keyframe on "
                                        "the joint itself."),
    "moved_with_hand": lambda v, t: (
        f"Your points travel only {_pct(v)} as far as the hand does in the other camera "
        "views: follow each joint as the hand moves."),
    "anchored_median_px": lambda v, t: (
        f"Your landmarks are a median {v:.1f} px from the object point they mark (aim for "
        f"under {t:.0f} px): keep each one on the same spot of the object."),
    "anchored_p90_px": lambda v, t: (f"A tenth of your landmark positions are more than "
                                     f"{v:.0f} px off the object point they mark."),
    "anchored_visible_occluded": lambda v, t: (
        f"You marked your landmarks occluded in {_pct(v)} of the frames where they can be "
        "seen; mark a landmark occluded only while something hides it."),
    "anchored_hidden_visible": lambda v, t: (
        f"You kept your landmarks visible in {_pct(v)} of the frames where the object turns "
        "them away or something hides them."),
    "anchored_drift_px": lambda v, t: (f"Your landmarks drift off their spot ({v:.0f} px "
                                       "more by the end of the clip)."),
    "anchored_fraction": lambda v, t: ("Your landmarks are not on the object: place both on "
                                       "the highlighted object."),
    "landmark_separation_mm": lambda v, t: (
        f"Your two landmarks mark one spot of the object ({v:.0f} mm apart): pick two "
        f"distinct points at least {t:.0f} mm apart on it and follow each one."),
    "moved_with_object": lambda v, t: (
        f"Your landmarks travel only {_pct(v)} as far as the object does in the other camera "
        "views: follow each landmark as the object moves."),
    "checks_accepted": lambda v, t: (
        f"You kept {v:.0f} suggested position(s) that were shown {CHECK_OFFSET_PX:.0f} px off "
        "the point on purpose: look at every suggestion on its frame and drag it onto the "
        "point before you accept it."),
}


def _readable(name: str) -> str:
    return name.replace("_", " ")


def _swap_sentence(swap: dict) -> str:
    frames = format_spans([swap["frames"]])
    if swap["kind"] == "mirror":
        return (f"Your finger order was mirrored in {frames} (thumb labelled as the little "
                f"finger, index as ring): check which hand you are labelling.")
    a, b = swap["fingers"]
    return (f"Your {a} and {b} finger labels were swapped in {frames} ({swap['error_px']:.0f} px "
            f"from where the other views place them, {swap['error_swapped_px']:.0f} px once "
            f"exchanged).")


def _explained_by_swap(issue: dict, swaps: list[dict], names: list[str]) -> bool:
    """An issue on a swapped finger inside the swap's frames needs no sentence of its own."""
    name = names[issue["point"]] if issue["point"] < len(names) else ""
    for swap in swaps:
        fingers = ("thumb", "index", "ring", "little") if swap["kind"] == "mirror" \
            else swap["fingers"]
        lo, hi = swap["frames"]
        if name.split("_")[0] in fingers and issue["frames"][0] <= hi and issue["frames"][1] >= lo:
            return True
    return False


def _issue_text(issue: dict, name: str) -> str:
    frames, error = format_spans([issue["frames"]]), issue["error_px"] or 0.0
    if issue.get("about") == "silhouette":
        return f"the {name} was {error:.0f} px off the object in {frames}"
    if issue.get("about") == "anchored":
        return f"the {name} was {error:.0f} px off the object point it marks in {frames}"
    if issue.get("about") == "stretch":
        first, last = issue["frames"][:2]
        return (f"the {name} moves {error:.0f} px between frames {first} and {last} that "
                "your track does not follow (add a keyframe where it turns)")
    if issue.get("about") == "jump":
        first, last = issue["frames"][:2]
        return f"the {name} jumped {error:.0f} px between frames {first} and {last}"
    views = issue.get("views")
    where = f"the other {views} camera views" if views else "the other camera views"
    return f"the {name} was {error:.0f} px from where {where} place it in {frames}"


def _issue_sentence(issues: list[dict], names: list[str], limit: int = 3) -> str:
    parts = []
    for issue in issues[:limit]:
        name = _readable(names[issue["point"]]) if issue["point"] < len(names) \
            else f"point {issue['point']}"
        parts.append(_issue_text(issue, name))
    if not parts:
        return ""
    more = f" ({len(issues) - limit} more spans like these)" if len(issues) > limit else ""
    return "Check these frames: " + "; ".join(parts) + more + "."


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
        reasons.append(_checks_reason(qc.metrics, level) if name == "checks_accepted"
                       else f"{name} {value:.3g} {sign} {limit:.3g} ({level})")
    undecided = _decided_nothing(qc.metrics)
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
                    feedback=_feedback(qc, swaps, worst, thresholds, point_names, outcome))


def _count(metrics: dict[str, float | None], name: str) -> int:
    value = metrics.get(name)
    return int(value) if value is not None else 0


def _checks_reason(metrics: dict[str, float | None], level: str) -> str:
    """The reason of a crossed checks_accepted threshold, with the counts behind it."""
    accepted = _count(metrics, "checks_accepted")
    seen = accepted + _count(metrics, "checks_corrected")
    verdict = "suggestions were accepted without looking" if level == "reject" \
        else "a suggestion may have been accepted without looking (review)"
    return (f"accepted {accepted} of {seen} check suggestions unchanged (each shown "
            f"{CHECK_OFFSET_PX:.0f} px off the point): {verdict}")


def _decided_nothing(metrics: dict[str, float | None]) -> bool:
    """Every shown position is a pre-filled suggestion left unchanged: nothing of the worker's
    own to judge. Reviewed, not rejected: the suggestions may well be right (a worker who
    kept check suggestions is rejected by those)."""
    return metrics.get("decided_fraction") == 0.0


def _feedback(qc: AssignmentQC, swaps: list[dict], worst: dict[str, tuple],
              thresholds: dict[str, float], names: list[str], outcome: str) -> str:
    sentences = [_swap_sentence(s) for s in swaps]
    if _decided_nothing(qc.metrics):
        sentences.append("Every position you sent was a suggestion left unchanged: check each "
                         "one on its frame and correct the ones that are off.")
    if outcome != "approve":
        issues = [i for i in qc.issues if not _explained_by_swap(i, swaps, names)]
        sentences.append(_issue_sentence(issues, names))
    for _, name, value, limit, worse in worst.values():
        if name in _ADVICE:
            # Advise the review threshold: that is what a good label stays within.
            sentences.append(_ADVICE[name](value, thresholds.get(f"{name}.review_{worse}", limit)))
    if outcome == "approve":
        median = qc.metrics.get("median_error_px")
        agree = f" (median error {median:.1f} px)" if median is not None else ""
        sentences.append(f"Thank you: your labels agree with the other camera views{agree}.")
    if qc.provisional:
        sentences.append("Fewer than 3 camera views could be compared, so this check is "
                         "provisional and a person will look at it.")
    return " ".join(s for s in sentences if s)
