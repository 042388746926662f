"""What QC says about an assignment in words: short reasons for admins, and feedback that
speaks to the worker, naming the joints, frames and distances."""

from __future__ import annotations

from collections.abc import Callable

from worker.assist.checks import CHECK_OFFSET_PX
from worker.quality.metrics import AssignmentQC
from worker.tracks.spans import format_spans


def _pct(value: float) -> str:
    return f"{100.0 * value:.0f}%"


# One sentence per failing metric, for the worker; {v} the value, {t} the threshold.
ADVICE: dict[str, Callable[[float, float], str]] = {
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


def swap_sentence(swap: dict) -> str:
    frames = format_spans([swap["frames"]])
    if swap["kind"] == "mirror":
        return (f"Your finger order was mirrored in {frames} (thumb labelled as the little "
                f"finger, index as ring): check which hand you are labelling.")
    a, b = swap["fingers"]
    return (f"Your {a} and {b} finger labels were swapped in {frames} ({swap['error_px']:.0f} px "
            f"from where the other views place them, {swap['error_swapped_px']:.0f} px once "
            f"exchanged).")


def explained_by_swap(issue: dict, swaps: list[dict], names: list[str]) -> bool:
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


def issue_sentence(issues: list[dict], names: list[str], limit: int = 3) -> str:
    parts = []
    for issue in issues[:limit]:
        name = _readable(names[issue["point"]]) if issue["point"] < len(names) \
            else f"point {issue['point']}"
        parts.append(_issue_text(issue, name))
    if not parts:
        return ""
    more = f" ({len(issues) - limit} more spans like these)" if len(issues) > limit else ""
    return "Check these frames: " + "; ".join(parts) + more + "."


def _count(metrics: dict[str, float | None], name: str) -> int:
    value = metrics.get(name)
    return int(value) if value is not None else 0


def checks_reason(metrics: dict[str, float | None], level: str) -> str:
    """The reason of a crossed checks_accepted threshold, with the counts behind it."""
    accepted = _count(metrics, "checks_accepted")
    seen = accepted + _count(metrics, "checks_corrected")
    verdict = "suggestions were accepted without looking" if level == "reject" \
        else "a suggestion may have been accepted without looking (review)"
    return (f"accepted {accepted} of {seen} check suggestions unchanged (each shown "
            f"{CHECK_OFFSET_PX:.0f} px off the point): {verdict}")


def kept_checks_sentence(cells: list[list[int]], names: list[str]) -> str:
    """The planted cells a worker kept, by point and frame: "The suggestions placed wrong on
    purpose that you kept: index pip at frame 4; thumb tip at frames 7 and 9." """
    by_point: dict[int, list[int]] = {}
    for point, frame in cells:
        by_point.setdefault(point, []).append(frame)
    parts = []
    for point, frames in sorted(by_point.items()):
        name = _readable(names[point]) if point < len(names) else f"point {point}"
        shown = sorted(frames)
        listed = (f"frame {shown[0]}" if len(shown) == 1
                  else "frames " + ", ".join(map(str, shown[:-1])) + f" and {shown[-1]}")
        parts.append(f"{name} at {listed}")
    if not parts:
        return ""
    return ("The suggestions placed wrong on purpose that you kept: " + "; ".join(parts)
            + ".")


def decided_nothing(metrics: dict[str, float | None]) -> bool:
    """Every shown position is a pre-filled suggestion left unchanged, and the worker changed
    nothing else either (``own_keyframes``: no point marked hidden, moved or placed): nothing
    of the worker's own to judge. Reviewed, not rejected: the suggestions may well be right (a
    worker who kept check suggestions is rejected by those). A worker who marked hidden the
    suggestions it saw covered decided those frames, though none of its visible positions is
    its own."""
    return metrics.get("decided_fraction") == 0.0 and not metrics.get("own_keyframes")


def feedback(qc: AssignmentQC, swaps: list[dict], worst: dict[str, tuple],
              thresholds: dict[str, float], names: list[str], outcome: str) -> str:
    sentences = [swap_sentence(s) for s in swaps]
    if decided_nothing(qc.metrics):
        sentences.append("Every position you sent was a suggestion left unchanged: check each "
                         "one on its frame and correct the ones that are off.")
    if outcome != "approve":
        issues = [i for i in qc.issues if not explained_by_swap(i, swaps, names)]
        sentences.append(issue_sentence(issues, names))
    if "checks_accepted" in worst:
        sentences.append(kept_checks_sentence(qc.kept_checks, names))
    for _, name, value, limit, worse in worst.values():
        if name in ADVICE:
            # Advise the review threshold: that is what a good label stays within.
            sentences.append(ADVICE[name](value, thresholds.get(f"{name}.review_{worse}", limit)))
    if outcome == "approve":
        median = qc.metrics.get("median_error_px")
        agree = f" (median error {median:.1f} px)" if median is not None else ""
        sentences.append(f"Thank you: your labels agree with the other camera views{agree}.")
    if qc.provisional:
        sentences.append("Fewer than 3 camera views could be compared, so this check is "
                         "provisional and a person will look at it.")
    return " ".join(s for s in sentences if s)
