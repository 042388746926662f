"""worker.quality.support and QC with one worker per view (as DexYCB labels every view once).

The scene of test_qc_consensus: a ring of cameras around a moving 21-joint hand, labels from
the simulated annotator profiles through the page's keyframes and interpolation.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.quality.test_qc_consensus import (
    camera_ring,
    make_label,
    moving_hand,
    truth_pixels,
)
from worker.geometry.refine import CameraStack
from worker.quality.consensus import score_hand
from worker.quality.decide import decide, learn_thresholds
from worker.quality.support import normalised_errors, reference_spread, spread_px
from worker.synth.annotators import swap_window


def _spread(cams, point: np.ndarray, weights: float = 0.25) -> np.ndarray:
    """(L, 2, 2) spread of every view's leave-one-out reference of one point seen by all."""
    inliers = np.ones((1, len(cams)), bool)
    return reference_spread(CameraStack.of(cams), point[None], inliers,
                            np.full(len(cams), weights), np.arange(len(cams)))[0]


class TestReferenceSpread:
    def test_more_views_fix_the_reference_more_tightly(self):
        cams, point = camera_ring(8), np.array([0.0, 0.0, 0.05])
        three = spread_px(_spread(cams[::3], point))
        eight = spread_px(_spread(cams, point))
        assert np.all(three > 1.5 * np.median(eight))

    def test_a_narrow_baseline_leaves_the_reference_loose(self):
        # Seen from the side (view 4, 90 degrees off), two views 22.5 degrees apart leave the
        # point loose along their common line of sight; two views 135 degrees apart do not.
        cams, point = camera_ring(16), np.array([0.0, 0.0, 0.05])
        narrow = spread_px(_spread([cams[4], cams[0], cams[1]], point))[0]
        wide = spread_px(_spread([cams[4], cams[1], cams[7]], point))[0]
        assert narrow > 2.0 * wide

    def test_two_views_give_no_verdict_the_three_views_rule(self):
        cams, point = camera_ring(8), np.array([0.0, 0.0, 0.05])
        assert np.isnan(_spread(cams[:2], point)).all()
        assert np.isfinite(_spread(cams[:3], point)).all()

    def test_untrusted_labels_do_not_count_as_a_view(self):
        cams, point = camera_ring(8), np.array([0.0, 0.0, 0.05])
        inliers = np.ones((1, 3), bool)
        spread = reference_spread(CameraStack.of(cams[:3]), point[None], inliers,
                                  np.full(3, 0.25), np.arange(3),
                                  trusted=np.array([True, True, False]))[0]
        # Label 2 still has its two trusted others; labels 0 and 1 have one each.
        assert np.isnan(spread[:2]).all() and np.isfinite(spread[2]).all()

    def test_bad_shapes_raise_naming_them(self):
        cams = camera_ring(3)
        with pytest.raises(ValueError, match=r"\(N=1, 3\).*\(L=3,\)"):
            reference_spread(CameraStack.of(cams), np.zeros((2, 3)), np.ones((1, 3), bool),
                             np.ones(3), np.arange(3))


class TestNormalisedErrors:
    def test_an_exact_reference_leaves_the_error_as_it_is(self):
        r = np.array([[3.0, 4.0]])
        assert normalised_errors(r, np.zeros((1, 2, 2)), 2.0)[0] == pytest.approx(5.0)

    def test_a_loose_reference_shrinks_the_error_along_its_spread_only(self):
        spread = np.array([[[16.0, 0.0], [0.0, 0.0]]])  # 4 px loose along x
        along = normalised_errors(np.array([[6.0, 0.0]]), spread, 2.0)[0]
        across = normalised_errors(np.array([[0.0, 6.0]]), spread, 2.0)[0]
        assert along < 3.0 and across == pytest.approx(6.0)

    def test_missing_spread_is_not_scored(self):
        assert np.isnan(normalised_errors(np.ones((1, 2)), np.full((1, 2, 2), np.nan), 2.0)[0])


@pytest.fixture(scope="module")
def four_views():
    """Four views, one worker each: two careful, a sloppy one and a swapper."""
    cams = camera_ring(8)[::2]
    truth_xy = truth_pixels(cams, moving_hand())
    labels = [make_label("careful-0", 0, truth_xy, "careful", 1),
              make_label("careful-1", 1, truth_xy, "careful", 2),
              make_label("sloppy-2", 2, truth_xy, "sloppy", 3),
              make_label("swapper-3", 3, truth_xy, "swapper", 4)]
    report = score_hand(cams, labels)
    thresholds = learn_thresholds([a.metrics for a in report.assignments.values()])
    names = [f"joint {j}" for j in range(21)]
    return report, {k: decide(a, thresholds, names) for k, a in report.assignments.items()}


class TestOneWorkerPerView:
    def test_careful_work_is_approved_at_four_views(self, four_views):
        _, decisions = four_views
        assert decisions["careful-0"].outcome == "approve"
        assert decisions["careful-1"].outcome == "approve"

    def test_sloppy_work_is_flagged_at_four_views(self, four_views):
        _, decisions = four_views
        assert decisions["sloppy-2"].outcome != "approve"

    def test_a_swap_is_found_without_a_second_worker_in_its_view(self, four_views):
        report, decisions = four_views
        swaps = report.assignments["swapper-3"].swaps
        lo, hi = swap_window(moving_hand().shape[0])
        assert [s["fingers"] for s in swaps] == [["ring", "little"]]
        assert lo - 2 <= swaps[0]["frames"][0] and swaps[0]["frames"][1] <= hi + 2
        assert decisions["swapper-3"].outcome == "reject"
        assert not any(report.assignments[k].swaps for k in ("careful-0", "careful-1"))

    def test_a_careful_label_in_two_usable_views_is_provisional(self):
        # Two careful views and two spammers: no careful point has two trusted other views.
        cams = camera_ring(8)[::2]
        truth_xy = truth_pixels(cams, moving_hand())
        labels = [make_label("careful-0", 0, truth_xy, "careful", 1),
                  make_label("careful-1", 1, truth_xy, "careful", 2),
                  make_label("spammer-2", 2, truth_xy, "spammer", 3),
                  make_label("spammer-3", 3, truth_xy, "spammer", 4)]
        report = score_hand(cams, labels)
        assert report.assignments["careful-0"].provisional
        assert report.assignments["careful-0"].metrics["median_error_px"] is None
