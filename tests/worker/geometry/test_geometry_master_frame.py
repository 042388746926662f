"""Projection, refinement, triangulation and leave-one-out residuals in a capture's master frame
(world = camera 0's frame, as in DexYCB), where the world origin is a camera centre: points
there, or points that could not be triangulated, must give NaN (no image, no estimate) without
a numpy warning, and every other point exactly what it gives alone."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from tests.worker.geometry.test_triangulate import _observe, _points, _ring
from worker.geometry.cameras import CameraModel, project_points
from worker.geometry.refine import CameraStack, project_stack, refine_points
from worker.geometry.triangulate import leave_one_out_residuals, triangulate_points


@pytest.fixture(autouse=True)
def numpy_warnings_fail() -> None:
    """Any warning (divide by zero, invalid value, all-NaN slice) fails the test."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def _master_frame(cams: list[CameraModel]) -> tuple[list[CameraModel], np.ndarray]:
    """The cameras re-expressed in camera 0's frame (camera 0 at the origin, identity pose),
    and the (3, 4) map from the old world into the new one."""
    T0 = np.vstack([cams[0].T_cam_to_world, [0.0, 0.0, 0.0, 1.0]])
    to_master = np.linalg.inv(T0)
    out = [CameraModel(c.K, c.dist, (to_master @ np.vstack([c.T_cam_to_world, [0, 0, 0, 1]]))[:3],
                       c.width, c.height) for c in cams]
    # Exactly the identity, as a capture's calibration writes the master camera.
    out[0] = CameraModel(cams[0].K, cams[0].dist, np.hstack([np.eye(3), np.zeros((3, 1))]),
                         cams[0].width, cams[0].height)
    return out, to_master[:3]


def _scene(views: int = 4, n: int = 40, seed: int = 0):
    """Cameras in the master frame and points (n, 3) in it with their pixels (n, V, 2)."""
    cams, to_master = _master_frame(_ring(views))
    X = _points(n, seed) @ to_master[:, :3].T + to_master[:, 3]
    noise = np.random.default_rng(seed + 1).normal(0.0, 0.5, (n, views, 2))
    return cams, X, _observe(cams, X) + noise


class TestProjectStack:
    def test_point_at_the_master_camera_has_no_image_there_and_projects_elsewhere(self):
        cams, X, _ = _scene()
        stack = CameraStack.of(cams)
        points = np.vstack([np.zeros(3), X[:3]])  # the origin: camera 0's centre, z = 0
        pix, z, jac = project_stack(stack, points, jacobian=True)
        assert z[0, 0] == 0.0
        assert np.isnan(pix[0, 0]).all() and np.isnan(jac[0, 0]).all()
        for v in range(1, len(cams)):
            assert np.allclose(pix[0, v], project_points(points[0], cams[v].K,
                                                         cams[v].T_cam_to_world, cams[v].dist))
        assert np.isfinite(jac[0, 1:]).all() and np.isfinite(pix[1:]).all()
        alone, _, alone_jac = project_stack(stack, X[:3], jacobian=True)
        assert np.array_equal(pix[1:], alone) and np.array_equal(jac[1:], alone_jac)


class TestRefinePoints:
    def test_start_at_a_camera_centre_stays_put_and_the_others_refine_as_alone(self):
        cams, X, pix = _scene()
        stack = CameraStack.of(cams)
        mask = np.ones(pix.shape[:2], bool)
        start = X + 0.003
        start[0] = 0.0  # its projection into camera 0 does not exist: no step can be taken
        out = refine_points(stack, pix, start, mask)
        assert np.array_equal(out[0], np.zeros(3))
        alone = refine_points(stack, pix[1:], start[1:], mask[1:])
        assert np.array_equal(out[1:], alone)
        assert np.abs(out[1:] - X[1:]).max() < 2e-3  # 0.5 px noise: about a millimetre


class TestTriangulatePoints:
    def test_points_seen_once_are_nan_and_the_rest_as_triangulated_alone(self):
        cams, X, pix = _scene()
        pix[:5, 1:] = np.nan  # seen by the master camera only
        pix[5:8] = np.nan  # seen by none
        tri = triangulate_points(cams, pix)
        assert np.isnan(tri.points[:8]).all() and not tri.inliers[:8].any()
        assert np.isnan(tri.errors_px[5:8]).all()
        alone = triangulate_points(cams, pix[8:])
        assert np.array_equal(tri.points[8:], alone.points)
        assert np.array_equal(tri.inliers[8:], alone.inliers)
        assert np.abs(tri.points[8:] - X[8:]).max() < 2e-3


class TestLeaveOneOutResiduals:
    def test_untriangulated_points_are_nan_and_the_rest_unchanged(self):
        cams, _, pix = _scene(views=5)
        pix[:6, 2:] = np.nan  # two views: triangulated, but no view can be left out
        pix[6:10, 1:] = np.nan  # one view: no point
        tri = triangulate_points(cams, pix)
        assert np.isnan(tri.points[6:10]).all() and np.isfinite(tri.points[:6]).all()
        loo = leave_one_out_residuals(cams, pix, tri.points, tri.inliers)
        assert np.isnan(loo[:10]).all()
        alone = leave_one_out_residuals(cams, pix[10:], tri.points[10:], tri.inliers[10:])
        assert np.array_equal(loo[10:], alone, equal_nan=True)
        assert np.isfinite(loo[10:]).all()
        # Leaving a view out can only make its residual larger.
        in_sample = np.linalg.norm(tri.errors_px[10:])
        assert np.linalg.norm(np.linalg.norm(loo[10:], axis=-1)) > in_sample
