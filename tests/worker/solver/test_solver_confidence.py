"""worker.solver.confidence.judge: when an object pose is trusted, and the reason when not."""

from __future__ import annotations

import numpy as np

from worker.solver.confidence import judge

NAN = float("nan")


def test_a_well_seen_pose_is_trusted_fully() -> None:
    assert judge("object 'box'", False, 4, 3.0, 6, 0.0, NAN) == (1.0, None)
    confidence, reason = judge("object 'box'", False, 4, 3.0, 6, 0.0, 2.0)
    assert reason is None and np.isclose(confidence, 0.9)  # 2 mm from the grip


def test_a_held_object_seen_by_one_depth_view_and_no_landmark_is_flagged_saying_so() -> None:
    confidence, reason = judge("grasped object 'mug'", False, 0, NAN, 1, 0.0, 2.0)
    assert reason == "grasped object 'mug' seen by 1 view in depth, no landmark visible"
    assert confidence == 0.25


def test_each_kind_of_disagreement_is_flagged_with_its_measure() -> None:
    assert judge("object 'a'", False, 3, 3.0, 3, 0.4, NAN)[1] == \
        "object 'a': depth sees through 40% of its surface"
    assert judge("object 'a'", False, 3, 14.0, 3, 0.0, NAN)[1] == \
        "object 'a': its landmarks reproject 14 px off"
    assert judge("object 'a'", False, 3, 3.0, 3, 0.0, 12.5)[1] == \
        "object 'a': 12 mm from where the hand holds it"
    assert judge("object 'a'", False, 1, 3.0, 0, 0.0, NAN)[1] == "object 'a' seen by 1 view only"


def test_a_resting_pose_is_trusted_by_the_motion_prior_unless_depth_sees_through_it() -> None:
    assert judge("object 'a'", True, 0, NAN, 0, 0.0, NAN) == (1.0, None)
    confidence, reason = judge("object 'a'", True, 0, NAN, 2, 0.5, NAN)
    assert reason == "object 'a': depth sees through 50% of its surface where it rests"
    assert np.isclose(confidence, 0.0)
