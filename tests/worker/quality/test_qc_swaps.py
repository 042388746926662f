"""worker.quality.swaps: finger swaps and mirrored hands found against a reference."""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.quality.test_qc_consensus import (
    FRAMES,
    camera_ring,
    make_label,
    moving_hand,
    truth_pixels,
)
from worker.quality.consensus import score_hand
from worker.quality.swaps import find_swaps, hand_permutations, permutation_of, undo_swaps
from worker.synth.annotators import swap_window


@pytest.fixture(scope="module")
def view_truth() -> np.ndarray:
    """(F, 21, 2) true pixels of one view of the moving hand (fingers ~17 px apart)."""
    cams = camera_ring()
    return truth_pixels(cams, moving_hand())[0]


def _noisy(truth: np.ndarray, seed: int, sigma: float = 2.0) -> np.ndarray:
    return truth + np.random.default_rng(seed).normal(0.0, sigma, truth.shape)


def _exchange(xy: np.ndarray, perm: np.ndarray, first: int, last: int) -> np.ndarray:
    out = xy.copy()
    out[first:last + 1] = xy[first:last + 1][:, perm]
    return out


def _perm(kind: str, fingers: list[str]) -> np.ndarray:
    return permutation_of({"kind": kind, "fingers": fingers})


class TestFindSwaps:
    def test_ring_little_swap_is_reported_with_fingers_frames_and_errors(self, view_truth):
        xy = _exchange(_noisy(view_truth, 0), _perm("swap", ["ring", "little"]), 10, 22)
        swaps = find_swaps(xy, np.ones(xy.shape[:2], bool), view_truth)
        assert len(swaps) == 1
        swap = swaps[0]
        assert swap["kind"] == "swap" and swap["fingers"] == ["ring", "little"]
        assert swap["frames"] == [10, 22]
        # As labelled, the moved points sit about one finger spacing away.
        spacing = np.linalg.norm(view_truth[10:23, 13:17] - view_truth[10:23, 17:21], axis=-1)
        assert abs(swap["error_px"] - spacing.mean()) < 2.0 and swap["error_swapped_px"] < 4.0
        assert swap["message"] == "ring and little swapped in frames 10-22"

    def test_adjacent_index_middle_swap_names_those_fingers(self, view_truth):
        xy = _exchange(_noisy(view_truth, 1), _perm("swap", ["index", "middle"]), 0, 15)
        swaps = find_swaps(xy, np.ones(xy.shape[:2], bool), view_truth)
        assert [(s["fingers"], s["frames"]) for s in swaps] == [(["index", "middle"], [0, 15])]

    def test_mirrored_finger_order_is_reported_as_mirror(self, view_truth):
        xy = _exchange(_noisy(view_truth, 2), _perm("mirror", ["thumb", "little", "index", "ring"]),
                       5, 30)
        swaps = find_swaps(xy, np.ones(xy.shape[:2], bool), view_truth)
        assert [s["kind"] for s in swaps] == ["mirror"] and swaps[0]["frames"] == [5, 30]
        assert "mirrored" in swaps[0]["message"]

    @pytest.mark.parametrize("sigma", [2.0, 8.0])
    def test_noisy_labels_without_a_swap_report_none(self, view_truth, sigma):
        xy = _noisy(view_truth, 3, sigma)
        assert find_swaps(xy, np.ones(xy.shape[:2], bool), view_truth) == []

    def test_random_points_report_no_swap(self, view_truth):
        rng = np.random.default_rng(4)
        xy = rng.uniform(0, 1, view_truth.shape) * [639.0, 479.0]
        assert find_swaps(xy, np.ones(xy.shape[:2], bool), view_truth) == []

    def test_occluded_points_are_not_compared(self, view_truth):
        xy = _exchange(_noisy(view_truth, 5), _perm("swap", ["ring", "little"]), 10, 22)
        visible = np.ones(xy.shape[:2], bool)
        visible[:, 13:21] = False
        assert find_swaps(xy, visible, view_truth) == []

    def test_a_short_blip_is_not_a_swap(self, view_truth):
        xy = _exchange(_noisy(view_truth, 6), _perm("swap", ["ring", "little"]), 10, 11)
        assert find_swaps(xy, np.ones(xy.shape[:2], bool), view_truth) == []

    def test_mismatched_shapes_raise_naming_them(self, view_truth):
        with pytest.raises(ValueError, match=r"\(36, 21, 2\).*\(36, 20\)"):
            find_swaps(view_truth, np.ones((36, 20), bool), view_truth)


class TestPermutations:
    def test_every_candidate_is_its_own_inverse(self):
        for cand in hand_permutations():
            assert np.array_equal(cand.perm[cand.perm], np.arange(21))

    def test_undo_swaps_restores_the_labels(self, view_truth):
        swap = {"kind": "swap", "fingers": ["ring", "little"], "frames": [10, 22]}
        xy = _exchange(view_truth, permutation_of(swap), 10, 22)
        fixed, _ = undo_swaps(xy, np.ones(xy.shape[:2], bool), [swap])
        assert np.array_equal(fixed, view_truth)


class TestSwapsInScoring:
    def _pool(self, careful: int, swappers: int):
        cams = camera_ring()
        truth_xy = truth_pixels(cams, moving_hand())
        labels = [make_label(f"careful-{v}", v, truth_xy, "careful", v) for v in range(careful)]
        labels += [make_label(f"swapper-{v}", careful + v, truth_xy, "swapper", 50 + v)
                   for v in range(swappers)]
        return cams, labels

    def test_the_swapper_in_a_careful_pool_is_found_over_the_true_window(self):
        cams, labels = self._pool(7, 1)
        report = score_hand(cams, labels)
        assert [s["frames"] for s in report.assignments["swapper-0"].swaps] == \
            [list(swap_window(FRAMES))]
        assert not any(report.assignments[f"careful-{v}"].swaps for v in range(7))

    def test_swappers_outnumbering_careful_workers_are_still_the_ones_blamed(self):
        # Four swappers outvote two careful workers, so the first consensus is swapped; the
        # consensus jumping between the fingers at the span's edges gives it away.
        cams, labels = self._pool(2, 4)
        report = score_hand(cams, labels)
        for v in range(4):
            assert [s["fingers"] for s in report.assignments[f"swapper-{v}"].swaps] == \
                [["ring", "little"]]
        assert not any(report.assignments[f"careful-{v}"].swaps for v in range(2))
        assert report.assignments["careful-0"].metrics["median_error_px"] < 3.5
