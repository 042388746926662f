"""Choosing the views that pin a target's 3D: widest baselines first, then the weak frames."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest

from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at
from worker.geometry.view_choice import (
    EDGE_PX,
    MIN_MOVING_READINGS,
    HandInView,
    hand_in_view,
    initial_views,
    next_view,
    rig_centre,
    seen,
    start_views,
)

K = intrinsics_matrix(600.0, 600.0, 320.0, 240.0)


def ring(azimuths_deg: Sequence[float], radius: float = 1.0, height: float = 0.5,
         target: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> list[CameraModel]:
    """Cameras on a circle around the z axis, each looking at ``target``; world z up."""
    out = []
    for a in np.radians(azimuths_deg):
        eye = np.array([radius * np.cos(a), radius * np.sin(a), height])
        out.append(CameraModel(K=K, dist=None, T_cam_to_world=look_at(
            eye, np.asarray(target, float), np.array([0.0, 0.0, 1.0])), width=640, height=480))
    return out


class TestRigCentre:
    def test_the_point_every_camera_looks_at(self) -> None:
        cameras = ring([0, 70, 150, 260], target=(0.1, -0.05, 0.02))
        np.testing.assert_allclose(rig_centre(cameras), [0.1, -0.05, 0.02], atol=1e-9)

    def test_refuses_a_single_camera(self) -> None:
        with pytest.raises(ValueError, match="at least 2 cameras, got 1"):
            rig_centre(ring([0]))


def ray_sine(azimuth_deg: float) -> float:
    """Sine between the rays to two cameras of ``ring`` (elevation atan(0.5)) that are
    ``azimuth_deg`` apart: cos = cos(e)^2 cos(d) + sin(e)^2 = 0.8 cos(d) + 0.2."""
    return float(np.sin(np.arccos(0.8 * np.cos(np.radians(azimuth_deg)) + 0.2)))


class TestInitialViews:
    # 0 and 100 degrees apart give rays 86.5 degrees apart (the pair nearest right angles;
    # 0 and 175 are further apart but nearly on one line); then 175 keeps sines 0.80 and 0.91
    # to them, where 15 keeps only 0.23 to view 0.
    AZIMUTHS = (0, 15, 100, 175)

    def test_the_pair_nearest_right_angles_then_the_view_furthest_from_a_line(self) -> None:
        assert ray_sine(100) > ray_sine(175) and ray_sine(85) > ray_sine(15)
        chosen = initial_views(ring(self.AZIMUTHS), np.zeros(3), 3)
        assert chosen == [0, 2, 3]

    def test_eight_views_give_three_spread_around_the_ring(self) -> None:
        chosen = initial_views(ring([0, 20, 40, 100, 170, 200, 260, 290]), np.zeros(3), 3)
        azimuths = sorted([0, 20, 40, 100, 170, 200, 260, 290][i] for i in chosen)
        gaps = np.diff(azimuths + [azimuths[0] + 360])
        assert gaps.min() >= 70, azimuths

    def test_a_view_that_does_not_see_the_target_is_not_chosen(self) -> None:
        cameras = ring([*self.AZIMUTHS, 280])
        # View 2 turned away: the target is behind it; view 4 (280 degrees) takes its place.
        away = cameras[2].T_cam_to_world.copy()
        away[:, :3] = away[:, :3] @ np.diag([-1.0, 1.0, -1.0])
        cameras[2] = CameraModel(K=K, dist=None, T_cam_to_world=away, width=640, height=480)
        assert not seen(cameras, np.zeros((1, 3)))[2, 0]
        chosen = initial_views(cameras, np.zeros(3), 3)
        assert 2 not in chosen and len(set(chosen)) == 3

    def test_fewer_views_than_asked_gives_them_all(self) -> None:
        assert initial_views(ring([0, 90]), np.zeros(3), 3) == [0, 1]

    def test_refuses_a_count_below_one(self) -> None:
        with pytest.raises(ValueError, match="count must be at least 1, got 0"):
            initial_views(ring(self.AZIMUTHS), np.zeros(3), 0)

    def test_a_start_view_leads_and_the_rest_widen_the_baselines_from_it(self) -> None:
        # Started from view 1 (15 degrees), the view furthest from its line is 100 degrees
        # (sine 0.98 to it), then the one keeping the most to both: 175 (0.73 to 100, where
        # 0 keeps only 0.23 to view 1).
        assert initial_views(ring(self.AZIMUTHS), np.zeros(3), 3, first=1) == [1, 2, 3]
        assert initial_views(ring([0, 90]), np.zeros(3), 3, first=1) == [1, 0]

    def test_preferred_views_are_taken_before_wider_ones(self) -> None:
        # Of views 1, 2 and 3 alone, 175 keeps the most to 15 and 100; the widest pair (0,
        # 100) is passed over for the preferred.
        chosen = initial_views(ring(self.AZIMUTHS), np.zeros(3), 3, preferred={1, 2, 3})
        assert chosen == [1, 2, 3]
        # Too few preferred: the rest widen the baselines from them (from 175 degrees: 100, at
        # 75 degrees of azimuth, then 15, which keeps more to both than 0 does).
        assert ray_sine(160) > ray_sine(175)
        assert initial_views(ring(self.AZIMUTHS), np.zeros(3), 3, first=3, preferred=[3]) \
            == [3, 2, 1]

    def test_refuses_a_start_view_that_is_not_a_view(self) -> None:
        with pytest.raises(ValueError, match="first view 4 is not one of the 4 views"):
            initial_views(ring(self.AZIMUTHS), np.zeros(3), 3, first=4)


def moving_square(frames: int, at_mm: float, x0: int, step_px: int, side: int = 40,
                  table_mm: float = 1200.0) -> np.ndarray:
    """(frames, 120, 160) uint16 mm: a table at ``table_mm`` and a square of ``side`` px at
    ``at_mm`` whose left edge starts at ``x0`` and moves ``step_px`` a frame (cut by the
    image's edge where it leaves it)."""
    depth = np.full((frames, 120, 160), table_mm, np.uint16)
    for f in range(frames):
        left = x0 + f * step_px
        depth[f, 40:40 + side, max(left, 0):max(left + side, 0)] = at_mm
    return depth


class TestHandInView:
    def test_a_hand_inside_the_image_on_every_frame(self) -> None:
        found = hand_in_view(moving_square(6, 700.0, 20, 10))
        assert MIN_MOVING_READINGS <= 40 * 40
        assert found == HandInView(whole_first=True, whole_share=1.0, depth_mm=700.0)

    def test_a_hand_cut_by_the_edge_on_the_first_frame(self) -> None:
        # Starts 10 px past the left edge, inside from the second frame on.
        found = hand_in_view(moving_square(6, 700.0, -10, 20))
        assert not found.whole_first and found.whole_share == 1.0

    def test_a_hand_that_leaves_the_image(self) -> None:
        # Its right side reaches the edge (within EDGE_PX) on the last two of six frames.
        found = hand_in_view(moving_square(6, 700.0, 40, 20))
        assert 40 + 3 * 20 + 40 < 160 - EDGE_PX <= 40 + 4 * 20 + 40
        assert found.whole_first and found.whole_share == pytest.approx(3 / 5)

    def test_a_hand_too_small_to_follow(self) -> None:
        found = hand_in_view(moving_square(6, 700.0, 20, 10, side=20))
        assert not found.whole_first and found.whole_share == 0.0

    def test_missing_readings_are_not_a_moving_hand(self) -> None:
        depth = moving_square(6, 700.0, 20, 10)
        depth[:, :, 120:] = 0
        depth[::2, 100:, :] = 0
        found = hand_in_view(depth)
        assert found.whole_first and found.depth_mm == 700.0

    def test_refuses_a_single_frame(self) -> None:
        with pytest.raises(ValueError,
                           match=r"expected depth \(S >= 2, H, W\), got \(1, 120, 160\)"):
            hand_in_view(moving_square(1, 700.0, 20, 10))


class TestStartViews:
    def test_the_views_that_keep_the_hand_whole_farthest_first(self) -> None:
        views = [hand_in_view(moving_square(6, 500.0, -10, 20)),  # cut on the first frame
                 hand_in_view(moving_square(6, 700.0, 20, 10)),
                 None,  # no depth
                 hand_in_view(moving_square(6, 900.0, 40, 20)),  # leaves the image
                 hand_in_view(moving_square(6, 800.0, 20, 10)),
                 hand_in_view(moving_square(6, 700.0, 30, 10))]
        assert start_views(views) == [4, 1, 5]

    def test_none_when_no_view_keeps_the_hand_whole(self) -> None:
        assert start_views([None, hand_in_view(moving_square(6, 500.0, -10, 20))]) == []
        assert start_views([]) == []


class TestNextView:
    def test_the_view_that_sees_the_weak_points_from_a_new_angle(self) -> None:
        cameras = ring([0, 10, 90, 180])
        points = np.zeros((2, 1, 3))
        # Published: 0 and 10 degrees. 90 keeps 80 degrees of azimuth to view 1; 180, though
        # further, lies nearly on the line of view 0.
        view, score = next_view(cameras, [0, 1], [2, 3], points)
        assert view == 2 and score == pytest.approx(ray_sine(80), abs=1e-9)

    def test_a_view_that_cannot_see_the_weak_points_is_passed_over(self) -> None:
        cameras = ring([0, 10, 90, 60])
        # View 2 (the right angle) turned away from the scene: view 3 is chosen instead.
        away = cameras[2].T_cam_to_world.copy()
        away[:, :3] = away[:, :3] @ np.diag([-1.0, 1.0, -1.0])
        cameras[2] = CameraModel(K=K, dist=None, T_cam_to_world=away, width=640, height=480)
        view, score = next_view(cameras, [0, 1], [2, 3], np.zeros((3, 1, 3)))
        assert view == 3 and score == pytest.approx(ray_sine(50), abs=1e-9)
        assert next_view(cameras, [0, 1], [2], np.zeros((3, 1, 3)))[1] == 0.0

    def test_refuses_no_candidates_and_no_points(self) -> None:
        cameras = ring([0, 90, 180])
        with pytest.raises(ValueError, match="no candidate view"):
            next_view(cameras, [0], [], np.zeros((1, 1, 3)))
        with pytest.raises(ValueError, match="no finite point"):
            next_view(cameras, [0], [1], np.full((2, 1, 3), np.nan))
