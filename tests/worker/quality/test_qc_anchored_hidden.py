"""worker.quality.anchored: a landmark label that marks its object hidden all through.

A careful worker whose view never shows the object (it is out of the image, or behind
something) marks both landmarks occluded in every frame: nothing can be anchored, and that is
right, not a failure. A worker who marks an object in plain view hidden all through is judged
by the frames where the solved object shows.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.quality.test_qc_anchored import FRAMES, HEIGHT, WIDTH, box, poses
from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at
from worker.quality.anchored import score_anchored
from worker.quality.decide import decide, learn_thresholds
from worker.quality.metrics import AssignmentQC
from worker.quality.object_views import (
    DEPTH_WINDOW_PX,
    SHOWN_SHARE,
    at_depth_edge,
    covered,
    object_shown,
)
from worker.quality.solved_scene import SolvedObjects
from worker.quality.view_labels import ViewLabels

NAMES = ["landmark 1", "landmark 2"]


def camera() -> CameraModel:
    return CameraModel(intrinsics_matrix(615.0, 615.0, 320.0, 240.0), None,
                       look_at(np.array([0.1, -0.6, 0.25]), np.zeros(3),
                               np.array([0.0, 0.0, 1.0])), WIDTH, HEIGHT)


def scene(shift_m: float = 0.0) -> SolvedObjects:
    """The sliding box, moved ``shift_m`` along x (2 m puts it far outside the image)."""
    vertices, faces = box()
    moved = poses()
    moved[0, :, 0, 3] += shift_m
    return SolvedObjects([vertices], [faces], moved)


def all_hidden() -> ViewLabels:
    """Both landmarks marked occluded in every frame, no position placed."""
    return ViewLabels("hidden", 0, np.full((FRAMES, 2, 2), np.nan),
                      np.zeros((FRAMES, 2), bool), 90.0)


def outcome(qc: AssignmentQC) -> str:
    """The decision on the label alone (a new project: the strict ends of the bounds)."""
    return decide(qc, learn_thresholds([qc.metrics]), NAMES).outcome


class TestObjectShown:
    def test_a_box_in_front_of_the_camera_shows_its_near_side(self):
        share = object_shown(camera(), scene(), 0, None)
        assert share.shape == (FRAMES,)
        # Seen from above and in front, three faces of the cube show: 7 of its 8 corners
        # (6 where it has turned so that only two faces do); the far corner never.
        assert set(np.unique(share)) <= {0.75, 0.875}

    def test_a_box_outside_the_image_shows_nothing(self):
        assert np.all(object_shown(camera(), scene(2.0), 0, None) == 0.0)

    def test_a_depth_reading_in_front_hides_the_box(self):
        near = np.full((FRAMES, HEIGHT, WIDTH), 300, np.uint16)  # a surface 0.3 m away
        assert np.all(object_shown(camera(), scene(), 0, near) == 0.0)

    def test_frames_without_a_pose_are_unknown(self):
        solved = scene()
        solved.poses[0, :5] = np.nan
        share = object_shown(camera(), solved, 0, None)
        assert np.isnan(share[:5]).all() and np.isfinite(share[5:]).all()


class TestLabelMarkedHiddenThroughout:
    def test_an_object_that_never_shows_rightly_labelled_hidden_is_approved(self):
        qc = score_anchored(camera(), all_hidden(), scene(2.0), 0)
        assert qc.metrics["anchored_fraction"] is None
        assert qc.metrics["anchored_visible_occluded"] == 0.0
        assert outcome(qc) == "approve"

    def test_an_object_in_plain_view_labelled_hidden_is_rejected(self):
        qc = score_anchored(camera(), all_hidden(), scene(), 0)
        assert qc.metrics["anchored_visible_occluded"] == pytest.approx(1.0)
        assert outcome(qc) == "reject"

    def test_one_landmark_shown_is_anchored_alone(self):
        label = all_hidden()
        solved = scene()
        pose = solved.poses[0]
        point = np.array([-0.02, -0.05, 0.01])
        label.xy[:, 0] = camera().project(np.einsum("fij,j->fi", pose[:, :, :3], point)
                                          + pose[:, :, 3])
        label.visible[:, 0] = True
        qc = score_anchored(camera(), label, solved, 0)
        assert qc.metrics["anchored_fraction"] == 1.0
        assert qc.metrics["anchored_median_px"] < 1.0


def test_shown_share_is_a_fraction():
    assert 0.0 < SHOWN_SHARE < 1.0


class TestCoveredByDepth:
    """A point 0.7 m away at pixel (320, 240): the depth camera hides it only where the
    whole square around its pixel reads well in front of it."""

    @staticmethod
    def _covered(hand_to_col: int) -> bool:
        depth = np.full((1, HEIGHT, WIDTH), 700, np.uint16)
        depth[0, :, :hand_to_col + 1] = 650  # a hand 5 cm in front, up to that column
        return bool(covered(depth, camera(), np.array([0]), np.array([[320.0, 240.0]]),
                            np.array([0.7]))[0])

    def test_a_hand_over_the_whole_square_hides_the_point(self):
        assert self._covered(320 + DEPTH_WINDOW_PX + 5)

    def test_a_hand_edge_a_few_pixels_off_does_not(self):
        # The reading at the pixel is the hand's (a depth image 2 px off its colour image, or a
        # calibration a few px off), the point itself is in plain view beside it.
        assert not self._covered(322)
        assert self._covered(322 + DEPTH_WINDOW_PX)

    def test_a_hand_edge_across_the_square_is_neither_plainly_shown_nor_hidden(self):
        for hand_to_col, edge in ((310, False), (322, True), (318, True),
                                  (322 + DEPTH_WINDOW_PX, False)):
            depth = np.full((1, HEIGHT, WIDTH), 700, np.uint16)
            depth[0, :, :hand_to_col + 1] = 650
            assert at_depth_edge(depth, camera(), np.array([0]), np.array([[320.0, 240.0]]),
                                 np.array([0.7]))[0] == edge, hand_to_col

    def test_no_reading_hides_nothing(self):
        depth = np.zeros((1, HEIGHT, WIDTH), np.uint16)
        assert not covered(depth, camera(), np.array([0]), np.array([[320.0, 240.0]]),
                           np.array([0.7]))[0]
