"""worker.geometry.cameras: projection against OpenCV, frame changes, look_at, undistortion."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from worker.geometry.cameras import (
    camera_to_world,
    intrinsics_matrix,
    look_at,
    pixels_to_rays,
    project_camera_points,
    project_points,
    undistort_normalized,
    world_to_camera,
)
from worker.geometry.transforms import invert_pose

K = intrinsics_matrix(615.3, 612.8, 318.4, 243.1)
DIST = np.array([0.08, -0.15, 0.0012, -0.0008, 0.03])
UP = np.array([0.0, 0.0, 1.0])


def _camera(eye=(0.5, -0.6, 0.45), target=(0.0, 0.0, 0.05)) -> np.ndarray:
    return look_at(np.array(eye), np.array(target), UP)


def _points(n: int = 200, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-0.2, 0.2, (n, 3)) + [0.0, 0.0, 0.05]


def _cv2_project(X, K, T_cam_to_world, dist):
    T = invert_pose(T_cam_to_world)
    rvec, _ = cv2.Rodrigues(T[:, :3])
    pix, _ = cv2.projectPoints(X, rvec, T[:, 3], K, dist)
    return pix[:, 0]


class TestProjectPoints:
    def test_matches_opencv_with_distortion(self):
        T, X = _camera(), _points()
        np.testing.assert_allclose(project_points(X, K, T, DIST), _cv2_project(X, K, T, DIST),
                                   atol=1e-9, rtol=0)

    def test_matches_opencv_without_distortion(self):
        T, X = _camera(eye=(-0.7, 0.3, 0.6)), _points(seed=1)
        np.testing.assert_allclose(project_points(X, K, T), _cv2_project(X, K, T, np.zeros(5)),
                                   atol=1e-9, rtol=0)

    def test_keeps_batch_shape(self):
        X = _points(24).reshape(2, 3, 4, 3)
        assert project_points(X, K, _camera(), DIST).shape == (2, 3, 4, 2)

    def test_target_projects_to_principal_point(self):
        target = np.array([0.0, 0.0, 0.05])
        np.testing.assert_allclose(project_points(target, K, _camera()), K[:2, 2], atol=1e-9)

    @pytest.mark.parametrize(
        ("args", "message"),
        [
            ((np.zeros((5, 2)), K, np.eye(3, 4)),
             r"X_world must have shape \(\.\.\., 3\), got \(5, 2\)"),
            ((np.zeros(3), np.eye(4), np.eye(3, 4)), r"K must have shape \(3, 3\), got \(4, 4\)"),
            ((np.zeros(3), K, np.eye(4)), r"T_cam_to_world must have shape \(3, 4\), got \(4, 4\)"),
            ((np.zeros(3), K, np.eye(3, 4), np.zeros(4)),
             r"dist must have shape \(5,\).*got \(4,\)"),
        ],
    )
    def test_rejects_bad_shapes_naming_them(self, args, message):
        with pytest.raises(ValueError, match=message):
            project_points(*args)


class TestFrames:
    def test_world_camera_round_trip(self):
        T, X = _camera(), _points()
        np.testing.assert_allclose(camera_to_world(world_to_camera(X, T), T), X, atol=1e-12)

    def test_camera_centre_maps_to_origin(self):
        T = _camera()
        np.testing.assert_allclose(world_to_camera(T[:, 3], T), np.zeros(3), atol=1e-12)

    def test_project_camera_points_agrees_with_world_version(self):
        T, X = _camera(), _points()
        np.testing.assert_allclose(project_camera_points(world_to_camera(X, T), K, DIST),
                                   project_points(X, K, T, DIST), atol=1e-9)


class TestLookAt:
    def test_z_axis_points_at_target(self):
        eye, target = np.array([0.4, -0.5, 0.6]), np.array([0.05, 0.02, 0.1])
        T = look_at(eye, target, UP)
        direction = (target - eye) / np.linalg.norm(target - eye)
        np.testing.assert_allclose(T[:, 2], direction, atol=1e-12)
        np.testing.assert_allclose(T[:, 3], eye)
        assert world_to_camera(target, T)[2] > 0

    def test_is_a_proper_rotation_with_y_down(self):
        T = _camera()
        np.testing.assert_allclose(T[:, :3].T @ T[:, :3], np.eye(3), atol=1e-12)
        assert np.linalg.det(T[:, :3]) == pytest.approx(1.0)
        assert T[:, 1] @ UP < 0  # image y points down, against world up

    def test_point_above_target_appears_higher_in_image(self):
        T = _camera()
        lower, upper = project_points(np.array([[0, 0, 0.05], [0, 0, 0.15]]), K, T)
        assert upper[1] < lower[1]

    def test_rejects_up_parallel_to_view(self):
        with pytest.raises(ValueError, match="parallel"):
            look_at(np.array([0.0, 0.0, 1.0]), np.zeros(3), UP)


class TestUndistort:
    def test_inverts_distortion(self):
        xy = np.random.default_rng(2).uniform(-0.5, 0.5, (500, 2))
        pix = project_camera_points(np.column_stack([xy, np.ones(len(xy))]), K, DIST)
        rays = pixels_to_rays(pix, K, DIST)
        np.testing.assert_allclose(rays[:, :2], xy, atol=1e-10)

    def test_matches_opencv_undistort(self):
        pix = np.random.default_rng(3).uniform([0, 0], [640, 480], (100, 2))
        ours = pixels_to_rays(pix, K, DIST)[:, :2]
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
        ref = cv2.undistortPoints(pix[:, None], K, DIST, criteria=criteria)[:, 0]
        np.testing.assert_allclose(ours, ref, atol=1e-9)

    def test_no_distortion_is_identity(self):
        xy = np.array([[0.1, -0.2]])
        np.testing.assert_array_equal(undistort_normalized(xy, None), xy)
