"""worker.geometry.transforms: rotations against scipy, pose algebra, MANO pose_m re-framing."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from worker.geometry.transforms import (
    axis_angle_to_matrix,
    axis_angle_to_quaternion,
    compose_poses,
    invert_pose,
    make_pose,
    matrix_to_axis_angle,
    matrix_to_quaternion,
    quaternion_to_matrix,
    transform_points,
    transform_pose_m,
)

RNG = np.random.default_rng(0)
AXIS_ANGLES = np.vstack([
    RNG.normal(size=(200, 3)) * 1.2,
    [[0.0, 0.0, 0.0], [1e-9, 0.0, 0.0], [np.pi, 0.0, 0.0], [0.0, np.pi - 1e-7, 0.0]],
    np.array([[1.0, 2.0, -0.5]]) / np.linalg.norm([1.0, 2.0, -0.5]) * (np.pi - 1e-12),
])


def _random_pose(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return make_pose(Rotation.random(random_state=seed).as_matrix(), rng.normal(size=3))


class TestRotations:
    def test_axis_angle_to_matrix_matches_scipy(self):
        np.testing.assert_allclose(axis_angle_to_matrix(AXIS_ANGLES),
                                   Rotation.from_rotvec(AXIS_ANGLES).as_matrix(), atol=1e-12)

    def test_matrix_to_axis_angle_round_trips_including_pi(self):
        back = axis_angle_to_matrix(matrix_to_axis_angle(axis_angle_to_matrix(AXIS_ANGLES)))
        np.testing.assert_allclose(back, axis_angle_to_matrix(AXIS_ANGLES), atol=1e-9)

    def test_small_angles_keep_precision(self):
        aa = np.array([[1e-9, -2e-9, 3e-10]])
        np.testing.assert_allclose(matrix_to_axis_angle(axis_angle_to_matrix(aa)), aa, rtol=1e-6)

    def test_quaternions_match_scipy_xyzw_up_to_sign(self):
        ours = matrix_to_quaternion(axis_angle_to_matrix(AXIS_ANGLES))
        ref = Rotation.from_rotvec(AXIS_ANGLES).as_quat()
        sign = np.sign(np.sum(ours * ref, axis=1, keepdims=True))
        np.testing.assert_allclose(ours, sign * ref, atol=1e-9)
        assert np.all(ours[:, 3] >= 0)

    def test_quaternion_to_matrix_matches_scipy(self):
        q = Rotation.random(50, random_state=1).as_quat()
        np.testing.assert_allclose(quaternion_to_matrix(q), Rotation.from_quat(q).as_matrix(),
                                   atol=1e-12)

    def test_axis_angle_to_quaternion_is_unit(self):
        q = axis_angle_to_quaternion(AXIS_ANGLES)
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)

    def test_bad_shape_is_named(self):
        message = r"axis_angle must have shape \(\.\.\., 3\), got \(4,\)"
        with pytest.raises(ValueError, match=message):
            axis_angle_to_matrix(np.zeros(4))
        with pytest.raises(ValueError, match="non-zero"):
            quaternion_to_matrix(np.zeros(4))


class TestPoses:
    def test_compose_then_invert_is_identity(self):
        a = _random_pose(2)
        np.testing.assert_allclose(compose_poses(a, invert_pose(a)), np.eye(3, 4), atol=1e-12)

    def test_compose_applies_right_pose_first(self):
        a, b, x = _random_pose(3), _random_pose(4), RNG.normal(size=(10, 3))
        np.testing.assert_allclose(transform_points(compose_poses(a, b), x),
                                   transform_points(a, transform_points(b, x)), atol=1e-12)

    def test_batched_compose(self):
        a = np.stack([_random_pose(s) for s in range(5)])
        assert compose_poses(a, invert_pose(a)).shape == (5, 3, 4)


def _lbs_like(pose_m: np.ndarray, canonical: np.ndarray, root: np.ndarray) -> np.ndarray:
    """Rigid part of MANO: rotate canonical points about the root joint, then translate."""
    rot = axis_angle_to_matrix(pose_m[:3])
    return (canonical - root) @ rot.T + root + pose_m[48:51]


class TestTransformPoseM:
    def test_moves_the_hand_like_the_rigid_transform(self):
        root = np.array([0.09, 0.006, -0.003])
        canonical = RNG.normal(scale=0.05, size=(30, 3))
        pose_m = np.concatenate([RNG.normal(size=3), RNG.normal(size=45), RNG.normal(size=3)])
        T = _random_pose(5)
        moved = transform_pose_m(pose_m, T, root)
        np.testing.assert_allclose(_lbs_like(moved, canonical, root),
                                   transform_points(T, _lbs_like(pose_m, canonical, root)),
                                   atol=1e-12)
        np.testing.assert_array_equal(moved[3:48], pose_m[3:48])

    def test_translation_is_not_just_rotated(self):
        root = np.array([0.1, 0.0, 0.0])
        T = make_pose(axis_angle_to_matrix(np.array([0.0, 0.0, np.pi / 2])), np.zeros(3))
        moved = transform_pose_m(np.zeros(51), T, root)
        # Naively rotating t = 0 gives 0; the root must move to R J0, so t' = R J0 - J0.
        np.testing.assert_allclose(moved[48:51], [-0.1, 0.1, 0.0], atol=1e-12)
