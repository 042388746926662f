"""worker.quality.decide: population thresholds, outcomes, reasons and worker feedback."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.worker.quality.test_qc_consensus import (
    camera_ring,
    make_label,
    moving_hand,
    truth_pixels,
)
from worker.hand import JOINT_NAMES
from worker.quality.bounds import MetricBound
from worker.quality.consensus import score_hand
from worker.quality.decide import QCThresholds, decide, learn_thresholds
from worker.quality.metrics import AssignmentQC
from worker.synth.qc_evaluation import assignment_plan, confusion, evaluate_hand_qc, span_overlap

NAMES = list(JOINT_NAMES)
# The review bounds of the median error, (strictest, most lenient) px.
REVIEW_MEDIAN = QCThresholds().bounds["median_error_px"].review


def _metrics(**overrides) -> dict:
    """The metrics of a clean careful label, with overrides."""
    base = {"median_error_px": 2.2, "mean_error_px": 2.5, "p90_error_px": 4.0,
            "outlier_fraction": 0.0, "jitter_px": 1.6, "motion_ratio": 1.02,
            "occluded_on_surface": 0.0, "completeness": 1.0, "working_time_s": 120.0}
    base.update(overrides)
    return base


def _qc(swaps=(), issues=(), provisional=False, **metrics) -> AssignmentQC:
    return AssignmentQC(key="a1", view=3, metrics=_metrics(**metrics), per_joint=[2.0] * 21,
                        per_frame=[2.0] * 72, swaps=list(swaps), issues=list(issues),
                        provisional=provisional)


@pytest.fixture(scope="module")
def thresholds() -> dict[str, float]:
    rng = np.random.default_rng(0)
    rows = [_metrics(median_error_px=float(e)) for e in rng.normal(2.3, 0.2, 30)]
    return learn_thresholds(rows)


class TestLearnThresholds:
    def test_threshold_is_median_plus_k_robust_sigmas_inside_the_bounds(self):
        lo, hi = REVIEW_MEDIAN
        errors = np.linspace(lo - 0.6, lo, 9)
        learned = learn_thresholds([_metrics(median_error_px=float(e)) for e in errors])
        mad = np.median(np.abs(errors - np.median(errors)))
        expected = np.median(errors) + 3.0 * 1.4826 * mad
        assert lo < expected < hi
        assert learned["median_error_px.review_above"] == pytest.approx(expected)

    def test_a_minority_of_bad_workers_barely_moves_the_threshold(self):
        good = [_metrics(median_error_px=3.0 + 0.04 * i) for i in range(20)]
        bad = [_metrics(median_error_px=200.0) for _ in range(6)]
        alone = learn_thresholds(good)["median_error_px.review_above"]
        pooled = learn_thresholds(good + bad)["median_error_px.review_above"]
        assert alone < 5.0 and abs(pooled - alone) < 0.6
        values = np.array([r["median_error_px"] for r in good + bad])
        assert values.mean() + 3 * values.std() > 100  # what a non-robust rule would allow

    def test_bounds_clamp_a_bad_population_and_a_tight_one(self):
        bad_pool = learn_thresholds([_metrics(median_error_px=30.0 + i) for i in range(20)])
        tight_pool = learn_thresholds([_metrics(median_error_px=2.0) for _ in range(20)])
        assert bad_pool["median_error_px.review_above"] == REVIEW_MEDIAN[1]
        assert tight_pool["median_error_px.review_above"] == REVIEW_MEDIAN[0]

    def test_small_population_uses_the_strict_end_of_the_bounds(self):
        learned = learn_thresholds([_metrics()] * 3)
        assert learned["median_error_px.review_above"] == REVIEW_MEDIAN[0]
        assert learned["motion_ratio.review_below"] == 0.6

    def test_keys_say_which_way_each_threshold_cuts_and_bounds_are_configurable(self):
        settings = QCThresholds(bounds={"jitter_px": MetricBound("above", (1.0, 2.0))})
        learned = learn_thresholds([_metrics()] * 10, settings)
        assert set(learned) == {"jitter_px.review_above", "motion_ratio.review_above",
                                "landmark_separation_mm.reject_below"}
        assert "motion_ratio.reject_below" in learn_thresholds([_metrics()] * 10)


class TestDecide:
    def test_clean_label_is_approved_with_thanks(self, thresholds):
        decision = decide(_qc(), thresholds, NAMES)
        assert decision.outcome == "approve" and decision.reasons == []
        assert "agree with the other camera views" in decision.feedback

    def test_swap_rejects_and_the_feedback_names_fingers_and_frames(self, thresholds):
        swap = {"kind": "swap", "fingers": ["ring", "little"], "frames": [20, 45],
                "error_px": 14.2, "error_swapped_px": 2.1,
                "message": "ring and little swapped in frames 20-45"}
        issue = {"point": 16, "frames": [22, 40], "error_px": 15.0, "views": 7}
        decision = decide(_qc(swaps=[swap], issues=[issue]), thresholds, NAMES)
        assert decision.outcome == "reject"
        assert "ring and little finger labels were swapped in frames 20-45" in decision.feedback
        assert "ring tip" not in decision.feedback  # explained by the swap

    def test_far_off_joint_is_named_with_views_frames_and_distance(self, thresholds):
        issue = {"point": 8, "frames": [30, 52], "error_px": 23.0, "views": 7}
        decision = decide(_qc(issues=[issue], p90_error_px=13.0), thresholds, NAMES)
        assert decision.outcome == "review"
        assert ("the index tip was 23 px from where the other 7 camera views place it in "
                "frames 30-52") in decision.feedback

    def test_borderline_error_goes_to_review_and_a_clear_fail_is_rejected(self, thresholds):
        assert decide(_qc(median_error_px=6.0), thresholds, NAMES).outcome == "review"
        assert decide(_qc(median_error_px=40.0), thresholds, NAMES).outcome == "reject"

    def test_copied_frames_are_rejected_with_advice(self, thresholds):
        decision = decide(_qc(motion_ratio=0.0), thresholds, NAMES)
        assert decision.outcome == "reject"
        assert "copying one frame to all" in decision.feedback

    def test_random_clicks_and_heavy_visibility_disagreement_count(self, thresholds):
        assert decide(_qc(motion_ratio=15.0), thresholds, NAMES).outcome == "review"
        occl = decide(_qc(occluded_on_surface=0.6), thresholds, NAMES)
        assert occl.outcome == "reject" and "occluded" in occl.feedback
        assert decide(_qc(outlier_fraction=0.9), thresholds, NAMES).outcome == "reject"

    def test_provisional_report_is_never_auto_rejected(self, thresholds):
        decision = decide(_qc(provisional=True, median_error_px=40.0), thresholds, NAMES)
        assert decision.outcome == "review" and decision.provisional
        assert "provisional" in decision.feedback

    def test_decision_is_json_friendly(self, thresholds):
        text = json.dumps(decide(_qc(median_error_px=6.0), thresholds, NAMES).to_dict())
        assert '"outcome": "review"' in text


class TestEndToEnd:
    def test_careful_pool_is_approved_and_bad_workers_are_caught(self):
        cams = camera_ring()
        truth_xy = truth_pixels(cams, moving_hand())
        labels = [make_label(f"careful-{v}", v, truth_xy, "careful", v) for v in range(8)]
        labels += [make_label(f"{p}-{v}", v, truth_xy, p, 100 + v)
                   for v, p in enumerate(["sloppy", "swapper", "lazy", "spammer"])]
        report = score_hand(cams, labels)
        learned = learn_thresholds([qc.metrics for qc in report.assignments.values()])
        outcome = {k: decide(qc, learned, NAMES).outcome for k, qc in report.assignments.items()}
        assert all(outcome[f"careful-{v}"] == "approve" for v in range(8))
        assert outcome["sloppy-0"] == "review"
        assert outcome["swapper-1"] == outcome["lazy-2"] == outcome["spammer-3"] == "reject"


class TestEvaluation:
    def test_every_profile_pool_is_sorted_and_the_swaps_are_found(self):
        cams = camera_ring()
        joints = moving_hand()
        truth_xy = truth_pixels(cams, joints)
        visible = np.ones(truth_xy.shape[:3], bool)
        plan = assignment_plan(len(cams), "all", np.random.default_rng(0))
        result = evaluate_hand_qc(cams, truth_xy, visible, None, plan, seed=3, point_names=NAMES)
        conf = result["confusion"]
        # No depth here, so the occluder (careful where it marks points visible) is not caught.
        assert conf["good_flagged"] == 0
        assert conf["table"]["occluder"]["approve"] == 8
        assert conf["bad_caught"] == conf["bad"] - 8
        assert all(s["overlap"] > 0.9 for s in result["swaps"]) and len(result["swaps"]) == 8
        json.dumps(result, allow_nan=False)

    def test_span_overlap_and_confusion_counts(self):
        assert span_overlap([20, 45], [20, 45]) == 1.0
        assert span_overlap([0, 9], [10, 19]) == 0.0
        assert span_overlap([25, 45], [20, 45]) == pytest.approx(21 / 26)
        conf = confusion({"a": "approve", "b": "review", "c": "approve"},
                         {"a": "careful", "b": "careful", "c": "lazy"})
        assert (conf["good"], conf["good_flagged"], conf["bad"], conf["bad_caught"]) == (2, 1, 1, 0)
