"""worker.quality.consensus: what a reviewer's replay draws, per label. The reference lies on
the true joints where two other views fix them (and is absent where they cannot), the errors
are the raw distances from the label to it, and a swapper's swapped fingers stand out there."""

from __future__ import annotations

import numpy as np

from tests.worker.quality.test_qc_consensus import (
    FRAMES,
    camera_ring,
    make_label,
    moving_hand,
    truth_pixels,
)
from worker.quality.consensus import score_hand
from worker.synth.annotators import swap_window

RING, LITTLE = list(range(13, 17)), list(range(17, 21))


def test_replay_reference_lies_on_the_truth_and_errors_are_distances_to_it() -> None:
    cams = camera_ring(6)
    truth = truth_pixels(cams, moving_hand())
    labels = [make_label("swapper", 0, truth, "swapper", 1)] + [
        make_label(f"c{v}", v, truth, "careful", 10 + v) for v in range(1, 6)]
    report = score_hand(cams, labels)
    assert set(report.replay) == {lab.key for lab in labels}
    replay = report.replay["swapper"]
    reference, errors = replay["reference"], replay["errors"]
    assert reference.shape == (FRAMES, 21, 2) and errors.shape == (FRAMES, 21)
    fixed = np.isfinite(reference).all(axis=-1)
    assert fixed.mean() > 0.9
    # The other five views place the joints within the careful workers' noise of the truth.
    assert np.median(np.linalg.norm(reference[fixed] - truth[0][fixed], axis=-1)) < 2.0
    # Errors are the label's distances to that reference wherever both exist.
    label = labels[0]
    both = fixed & np.isfinite(errors)
    assert np.allclose(errors[both],
                       np.linalg.norm(label.xy[both] - reference[both], axis=-1), atol=1e-6)
    lo, hi = swap_window(FRAMES)
    inside = np.nanmedian(errors[lo + 2:hi - 1][:, RING + LITTLE])
    outside = np.nanmedian(errors[:max(lo - 3, 1)][:, RING + LITTLE])
    # Neighbouring fingers are 2 cm (about 9 px) apart.
    assert inside > 6.0 and inside > 3 * outside, (inside, outside)


def test_replay_has_no_reference_where_fewer_than_two_other_views_fix_a_point() -> None:
    cams = camera_ring(2)
    truth = truth_pixels(cams, moving_hand())
    labels = [make_label(f"c{v}", v, truth, "careful", v) for v in range(2)]
    report = score_hand(cams, labels)
    for replay in report.replay.values():
        assert not np.isfinite(replay["reference"]).any()
        assert not np.isfinite(replay["errors"]).any()
