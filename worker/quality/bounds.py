"""How each QC metric is judged: which side is bad, and the bounds people set on the learned
review and reject thresholds (worker.quality.decide learns them from a project's population
and clamps them into these)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class MetricBound:
    """How one metric is judged. worse: "above" or "below" the threshold is bad.
    review, reject: (lowest, highest) values the learned threshold may take; reject None: the
    metric alone never rejects."""

    worse: Literal["above", "below"]
    review: tuple[float, float]
    reject: tuple[float, float] | None = None


# Pixel bounds suit 640x480 views. Hand errors are normalised to how well the other views
# fix each point (worker.quality.support), so they read the same at 8 views as at 4: a
# careful annotator (2 px per-axis noise, keyframes interpolated) scores a median of
# 1.6-1.9 px and a 90th percentile of 3.1-3.6 px; a sloppy one (8 px) 2.9-5.7 and 6.3-10.7
# (its raw errors, 7-8 px, shrink where the reference itself is loose). Object landmarks
# are judged against the silhouette. Fractions: careful workers leave ~0 outliers (sloppy
# ones 25-45%, so they are reviewed, not rejected, on that alone) and mark <2% of the
# points on the visible surface as occluded.
METRIC_BOUNDS: dict[str, MetricBound] = {
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
    # Drift (the track's error over the last third of the clip less that over the first):
    # a careful worker takes a tracked position it judges within 3 sigma of its click noise
    # (6 px, worker.synth.assisted.TOLERANCE_PX) and corrects beyond, so its track slides
    # up to that far before a correction, and the solved point adds a px or so: careful
    # assisted tracks drift 5-7.2 px (bench/cost.py, 24-frame crowds), keyframed ones up
    # to 6.8. A slide beyond a careful track's 90th percentile (anchored_p90_px) asks for a
    # look; a frozen or unchecked track drifts tens of px.
    "anchored_drift_px": MetricBound("above", (8.0, 10.0)),
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
    # Share of a hand track's steps from keyframe to keyframe whose interpolated stretch its
    # own view's images say the point left (worker.quality.stretch_qc; a step to the next
    # frame follows by construction): a careful worker keys where the path bends and
    # leaves 0-12% (the tracker's own slips); one keying every 4th frame through fast
    # motion 70-80%.
    "unfollowed_stretches": MetricBound("above", (0.2, 0.25), (0.45, 0.55)),
}

# Object landmarks are judged on their own shake (against the solved object's point,
# worker.quality.anchored, or beyond the other views' tracks, worker.quality.landmarks) where
# hands compare with a consensus. A careful worker who places a landmark on every frame
# (DexYCB's protocol, or dragging suggestions one by one) shakes with its click noise alone:
# 2 px per axis, i.i.d., gives sqrt(12) x 2 = 6.9 px/frame^2 RMS, above the hands' bounds.
# Random clicks shake tens of px, a swap or a slip leaps (jump_fraction).
OBJECT_BOUNDS: dict[str, MetricBound] = {
    "jitter_px": MetricBound("above", (8.0, 10.0)),
}


def kind_bounds(kind: str) -> dict[str, MetricBound]:
    """The metric bounds of a target kind ("hand" or "object"): METRIC_BOUNDS, with
    OBJECT_BOUNDS in place for objects."""
    return {**METRIC_BOUNDS, **OBJECT_BOUNDS} if kind == "object" else dict(METRIC_BOUNDS)
