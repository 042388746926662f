"""Evaluation of hand QC on a synthetic capture: simulated workers, scoring, confusion table.

Pure: ground truth arrays in, a JSON-friendly summary out (bench/qc.py prints it). The truth of
a capture is, per view, the true joint pixels and visibility (worker.synth.annotators'
hand_visibility), plus optional depth maps; simulated workers spoil it by profile.

good = careful; bad = every other profile. A bad assignment is caught when QC decides review or
reject; a good one is flagged when it does.
"""

from __future__ import annotations

import time

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.quality.consensus import score_hand
from worker.quality.decide import QCThresholds, decide, learn_thresholds
from worker.quality.hand_report import HandReport
from worker.quality.view_labels import ViewLabels
from worker.synth.annotators import PROFILES, annotate, draw_profiles, swap_window
from worker.tracks.interpolate import dense_track

GOOD_PROFILES = ("careful",)
SWAPPED_FINGERS = ["ring", "little"]


def assignment_plan(views: int, pattern: str, rng: np.random.Generator) -> list[tuple[int, str]]:
    """(view, profile) of every assignment: "all" = each view labelled once by every profile;
    "mixed" = each view labelled by one worker drawn from the mixed profile weights."""
    if pattern == "all":
        return [(v, p) for v in range(views) for p in PROFILES]
    if pattern == "mixed":
        return list(enumerate(draw_profiles(views, "mixed", rng)))
    raise ValueError(f"unknown pattern {pattern!r}; one of all, mixed")


def simulated_labels(truth_xy: np.ndarray, truth_visible: np.ndarray, size: tuple[int, int],
                     plan: list[tuple[int, str]], rng: np.random.Generator,
                     prefix: str = "a") -> tuple[list[ViewLabels], dict[str, str]]:
    """Labels of the planned assignments, through the same keyframes and interpolation as the
    annotation page. truth_xy: (V, F, P, 2) px; truth_visible: (V, F, P) bool; size (W, H) px.
    Returns the labels and {key: profile}."""
    labels, profiles = [], {}
    frames = truth_xy.shape[1]
    for i, (view, profile) in enumerate(plan):
        work = annotate(truth_xy[view], truth_visible[view], size, profile, rng)
        dense = [dense_track(track, frames) for track in work.tracks]
        key = f"{prefix}{i:03d}-v{view}-{profile}"
        labels.append(ViewLabels(key=key, view=view,
                                 xy=np.stack([d.xy for d in dense], axis=1),
                                 visible=np.stack([d.visible for d in dense], axis=1),
                                 working_time_s=150.0))
        profiles[key] = profile
    return labels, profiles


def span_overlap(a: list[int], b: list[int]) -> float:
    """Intersection over union of two inclusive frame spans."""
    inter = min(a[1], b[1]) - max(a[0], b[0]) + 1
    union = max(a[1], b[1]) - min(a[0], b[0]) + 1
    return max(inter, 0) / union


def _swap_check(report: HandReport, profiles: dict[str, str], frames: int) -> list[dict]:
    """For every swapper: the swaps QC reported, the best overlap (IoU) of a ring/little swap's
    span with the true window, and its largest end offset in frames."""
    lo, hi = swap_window(frames)
    rows = []
    for key, profile in profiles.items():
        if profile != "swapper":
            continue
        swaps = [s for s in report.assignments[key].swaps if s["fingers"] == SWAPPED_FINGERS]
        best = max(swaps, key=lambda s: span_overlap(s["frames"], [lo, hi]), default=None)
        rows.append({
            "key": key, "true_frames": [lo, hi],
            "overlap": 0.0 if best is None else round(span_overlap(best["frames"], [lo, hi]), 3),
            "end_offset": None if best is None else max(abs(best["frames"][0] - lo),
                                                        abs(best["frames"][1] - hi)),
            "reported": [{"fingers": s["fingers"], "frames": s["frames"]}
                         for s in report.assignments[key].swaps]})
    return rows


def confusion(outcomes: dict[str, str], profiles: dict[str, str]) -> dict:
    """Counts of approve/review/reject per profile, and the caught / flagged rates."""
    table = {p: {"approve": 0, "review": 0, "reject": 0} for p in sorted(set(profiles.values()))}
    for key, outcome in outcomes.items():
        table[profiles[key]][outcome] += 1
    good = [outcomes[k] for k, p in profiles.items() if p in GOOD_PROFILES]
    bad = [outcomes[k] for k, p in profiles.items() if p not in GOOD_PROFILES]
    return {"table": table,
            "bad": len(bad), "bad_caught": sum(o != "approve" for o in bad),
            "good": len(good), "good_flagged": sum(o != "approve" for o in good)}


def evaluate_hand_qc(cameras: list[CameraModel], truth_xy: np.ndarray, truth_visible: np.ndarray,
                     depth: dict[int, np.ndarray] | None, plan: list[tuple[int, str]],
                     seed: int = 0, bounds: QCThresholds | None = None,
                     point_names: list[str] | None = None) -> dict:
    """Simulate the planned assignments, score them together, decide, and compare with truth.

    Args:
        cameras: V views. truth_xy: (V, F, P, 2) true pixels. truth_visible: (V, F, P) bool.
        depth: optional {view: (F, H, W) uint16 mm}. plan: (view, profile) per assignment.
        seed: seeds the simulated workers. bounds: decision settings (defaults if None).
        point_names: P names for the feedback (default "point <i>").

    Returns:
        {"confusion": ..., "swaps": [...], "score_seconds": float, "thresholds": {...},
         "decisions": {key: {"profile", "outcome", "reasons", "feedback"}}}.
    """
    rng = np.random.default_rng(seed)
    size = (cameras[0].width, cameras[0].height)
    labels, profiles = simulated_labels(truth_xy, truth_visible, size, plan, rng)
    start = time.perf_counter()
    report = score_hand(cameras, labels, depth)
    seconds = time.perf_counter() - start
    bounds = bounds or QCThresholds()
    thresholds = learn_thresholds([a.metrics for a in report.assignments.values()], bounds)
    names = point_names or [f"point {p}" for p in range(truth_xy.shape[2])]
    decisions = {key: decide(qc, thresholds, names) for key, qc in report.assignments.items()}
    return {
        "confusion": confusion({k: d.outcome for k, d in decisions.items()}, profiles),
        "swaps": _swap_check(report, profiles, truth_xy.shape[1]),
        "score_seconds": round(seconds, 3),
        "provisional": report.provisional,
        "thresholds": thresholds,
        "decisions": {k: {"profile": profiles[k], "outcome": d.outcome, "reasons": d.reasons,
                          "feedback": d.feedback} for k, d in decisions.items()},
    }
