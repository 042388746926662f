"""Per-assignment quality metrics of one view's labels against a reference (the consensus).

Everything is in one camera view: F frames, P points (21 hand joints in DexYCB order or 2 object
landmarks), positions in image pixels (x right, y down). Errors are pixel distances between a
label and where the other views place the point. Outputs are plain floats, lists and dicts (None
for "not measurable"), so they go to JSON as they are. What the depth camera says of the
points' visibility comes from worker.assist.visibility (the rule pre-fill uses too).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from worker.assist.visibility import SurfaceCheck

# visible_behind_surface is a share of the points the depth camera finds covered, and only
# reads as one over at least this many (point, frame) pairs: careful work sees a covered point
# in a frame or two at an object's outline, where the reference sits a pixel off the edge, and
# 1 of 1 read "100 % marked visible" on an approved careful label (synthetic capture seed 31,
# 8 views, careful labels: 1, 0, 0, 0, 22, 55, 497 and 586 covered points, of which 1, 0, 0,
# 0, 1, 0, 1 and 5 marked visible).
MIN_COVERED_POINTS = 10
# A span of at least this many frames with errors above the issue threshold is reported.
ISSUE_MIN_FRAMES = 3
# Gaps of up to this many frames inside a span are bridged (a close miss mid-span).
ISSUE_GAP_FRAMES = 2


def num(value: float | np.floating | None, digits: int = 4) -> float | None:
    """A JSON-friendly float: None for None, NaN or infinity."""
    if value is None or not np.isfinite(value):
        return None
    return round(float(value), digits)


def num_list(values: np.ndarray, digits: int = 3) -> list[float | None]:
    return [num(v, digits) for v in np.asarray(values, dtype=np.float64).ravel()]


@dataclass
class AssignmentQC:
    """Quality of one assignment (one worker's labels of one view).

    metrics: named numbers (None where not measurable), see hand_metrics / score_landmarks.
    per_joint: (P,) median error per point, px. per_frame: (F,) median error per frame, px.
    swaps: detected label permutations (worker.quality.swaps). issues: spans where one point is
    far off: {"point", "frames": [first, last], "error_px", "views"}. provisional: too few
    other views to judge (never auto-rejected). kept_checks: [point, frame] check cells whose
    suggestion, placed wrong on purpose, was kept unchanged (worker.assist.checks).
    """

    key: str
    view: int
    metrics: dict[str, float | None]
    per_joint: list[float | None]
    per_frame: list[float | None]
    swaps: list[dict] = field(default_factory=list)
    issues: list[dict] = field(default_factory=list)
    provisional: bool = False
    kept_checks: list[list[int]] = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)


def _nan_median(values: np.ndarray, axis: int) -> np.ndarray:
    """np.nanmedian without the all-NaN warning: NaN where a slice has no value."""
    finite = np.isfinite(values)
    out = np.full(values.shape[:axis] + values.shape[axis + 1:], np.nan)
    has = finite.any(axis=axis)
    if has.any():
        moved = np.moveaxis(np.where(finite, values, np.nan), axis, -1)
        out[has] = np.nanmedian(moved[has], axis=-1)
    return out


def error_summary(errors: np.ndarray) -> dict[str, float | None]:
    """median, mean and 90th percentile (px) of the finite values of errors (F, P)."""
    e = errors[np.isfinite(errors)]
    if e.size == 0:
        return {"median_error_px": None, "mean_error_px": None, "p90_error_px": None}
    return {"median_error_px": num(np.median(e)), "mean_error_px": num(e.mean()),
            "p90_error_px": num(np.percentile(e, 90))}


def per_point_and_frame(errors: np.ndarray) -> tuple[list[float | None], list[float | None]]:
    """Median error per point (P,) and per frame (F,) of errors (F, P) px."""
    return num_list(_nan_median(errors, 0)), num_list(_nan_median(errors, 1))


def jitter_px(xy: np.ndarray, reference: np.ndarray) -> float | None:
    """Root-mean-square second difference (px per frame^2) of the label's offset from the
    reference, over runs of three frames where both exist. Removing the reference's motion
    leaves the label's own shake. xy, reference: (F, P, 2) px, NaN where absent."""
    d = xy - reference
    acc = d[2:] - 2.0 * d[1:-1] + d[:-2]
    ok = np.isfinite(acc).all(axis=-1)
    if not ok.any():
        return None
    return num(np.sqrt(np.mean(np.sum(acc[ok] ** 2, axis=-1))))


def motion_ratio(xy: np.ndarray, reference: np.ndarray) -> float | None:
    """Path length of the label divided by the reference's, over consecutive frame pairs where
    both have positions. xy, reference: (F, P, 2) px. ~1 for a good label, ~0 for one frame
    copied to all; None where the reference does not move (nothing to compare)."""
    step_label = np.linalg.norm(np.diff(xy, axis=0), axis=-1)
    step_ref = np.linalg.norm(np.diff(reference, axis=0), axis=-1)
    ok = np.isfinite(step_label) & np.isfinite(step_ref)
    ref_total = step_ref[ok].sum()
    if not ok.any() or ref_total < 1e-6:
        return None
    return num(step_label[ok].sum() / ref_total)


def static_fraction(xy: np.ndarray, still_px: float = 0.25) -> float | None:
    """Fraction of consecutive frame pairs in which no point of the label moves more than
    ``still_px``. xy: (F, P, 2) px."""
    step = np.linalg.norm(np.diff(xy, axis=0), axis=-1)
    has = np.isfinite(step).any(axis=1)
    if not has.any():
        return None
    moving = np.where(np.isfinite(step), step, 0.0).max(axis=1) > still_px
    return num(1.0 - moving[has].mean())


def completeness(xy: np.ndarray, visible: np.ndarray) -> float | None:
    """Share of (frame, point) entries that are placed or marked occluded: a point hidden all
    clip long needs no position. xy: (F, P, 2) px, NaN = no position; visible: (F, P)."""
    return num((np.isfinite(xy).all(axis=-1) | ~np.asarray(visible, bool)).mean())


def track_metrics(xy: np.ndarray, visible: np.ndarray, reference: np.ndarray,
                  working_time_s: float | None) -> dict[str, float | None]:
    """The label's own behaviour against a reference (consensus or gold) of the same view.

    xy: (F, P, 2) px, NaN = no position; visible: (F, P); reference: (F, P, 2) px, NaN where
    unknown. Returns jitter_px, motion_ratio, completeness, visible_fraction, working_time_s.
    """
    shown = np.where(visible[..., None], xy, np.nan)
    return {"jitter_px": jitter_px(shown, reference),
            "motion_ratio": motion_ratio(xy, reference),
            "completeness": completeness(xy, visible),
            "visible_fraction": num(visible.mean()),
            "working_time_s": num(working_time_s, 1)}


def depth_visibility(visible: np.ndarray, check: SurfaceCheck) -> dict[str, float | None]:
    """How often the label's visibility flags (F, P) contradict the view's depth map.

    Returns:
        visibility_disagreement (contradicted fraction of the judged points),
        occluded_on_surface (of the points on the surface, fraction marked occluded),
        visible_behind_surface (of the hidden points, fraction marked visible; None below
        MIN_COVERED_POINTS of them); None where nothing was judged.
    """
    on_surface, hidden = check.on_surface, check.hidden
    wrong = (on_surface & ~visible) | (hidden & visible)
    n_judged = on_surface.sum() + hidden.sum()

    def fraction(part: np.ndarray, whole: np.ndarray) -> float | None:
        return num(part.sum() / whole.sum()) if whole.any() else None

    return {"visibility_disagreement": num(wrong.sum() / n_judged) if n_judged else None,
            "occluded_on_surface": fraction(on_surface & ~visible, on_surface),
            "visible_behind_surface": fraction(hidden & visible, hidden)
            if hidden.sum() >= MIN_COVERED_POINTS else None}


def error_issues(errors: np.ndarray, threshold_px: float, other_views: np.ndarray | None = None,
                 min_frames: int = ISSUE_MIN_FRAMES) -> list[dict]:
    """Spans of frames where one point's error stays above ``threshold_px``.

    Args:
        errors: (F, P) px, NaN where not measured (a NaN frame neither starts nor breaks a span).
        threshold_px: what counts as far off.
        other_views: (F, P) number of other views behind the reference, for the message.
        min_frames: shortest span reported (frames over the threshold inside it).

    Returns:
        [{"point": p, "frames": [first, last], "error_px": median in the span, "views": n}],
        worst first.
    """
    issues = []
    for p in range(errors.shape[1]):
        far = np.flatnonzero(errors[:, p] > threshold_px)
        if far.size == 0:
            continue
        breaks = np.flatnonzero(np.diff(far) > ISSUE_GAP_FRAMES + 1)
        for run in np.split(far, breaks + 1):
            if run.size < min_frames:
                continue
            first, last = int(run[0]), int(run[-1])
            span = errors[first:last + 1, p]
            issue = {"point": p, "frames": [first, last],
                     "error_px": num(np.nanmedian(span[np.isfinite(span)]), 1)}
            if other_views is not None:
                issue["views"] = int(np.median(other_views[first:last + 1, p]))
            issues.append(issue)
    return sorted(issues, key=lambda i: -(i["error_px"] or 0.0))
