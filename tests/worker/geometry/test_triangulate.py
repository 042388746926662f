"""worker.geometry.triangulate: DLT, robust consensus, LM refinement, leave-one-out residuals."""

from __future__ import annotations

import numpy as np
import pytest

from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at
from worker.geometry.refine import CameraStack, project_stack
from worker.geometry.triangulate import (
    leave_one_out_residuals,
    triangulate_dlt,
    triangulate_points,
)

K = intrinsics_matrix(615.0, 612.0, 320.0, 240.0)
DIST = np.array([0.09, -0.17, 0.0015, -0.0009, 0.04])
UP = np.array([0.0, 0.0, 1.0])


def _ring(views: int = 8, dist: np.ndarray | None = DIST) -> list[CameraModel]:
    """Cameras on a ring 0.7 m around the origin, as in a capture rig, each aimed a little off
    the centre so that the points spread over the image (where distortion is strong)."""
    cams = []
    for i, a in enumerate(np.linspace(0.0, 2.0 * np.pi, views, endpoint=False)):
        eye = np.array([0.7 * np.cos(a), 0.7 * np.sin(a), 0.35 + 0.05 * (i % 2)])
        target = 0.15 * np.array([np.cos(a + 1.3), np.sin(a + 1.3), 0.3])
        cams.append(CameraModel(K, dist, look_at(eye, target, UP), 640, 480))
    return cams


def _points(n: int = 300, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-0.12, 0.12, (n, 3))


def _observe(cams: list[CameraModel], X: np.ndarray) -> np.ndarray:
    return np.stack([c.project(X) for c in cams], axis=1)


class TestTriangulateDlt:
    def test_recovers_points_exactly_from_noise_free_distorted_pixels(self):
        cams, X = _ring(), _points()
        assert np.abs(triangulate_dlt(cams, _observe(cams, X)) - X).max() < 1e-9

    def test_points_seen_by_fewer_than_two_views_are_nan(self):
        cams, X = _ring(4), _points(3)
        pix = _observe(cams, X)
        pix[0, 1:] = np.nan  # seen by view 0 only
        pix[1, :] = np.nan  # seen by none
        out = triangulate_dlt(cams, pix)
        assert np.isnan(out[:2]).all() and np.abs(out[2] - X[2]).max() < 1e-9

    def test_bad_pixel_shape_raises_naming_the_shape(self):
        with pytest.raises(ValueError, match=r"\(5, 3, 2\)"):
            triangulate_dlt(_ring(4), np.zeros((5, 3, 2)))


class TestTriangulatePoints:
    def test_recovers_points_exactly_and_keeps_every_view(self):
        cams, X = _ring(), _points()
        tri = triangulate_points(cams, _observe(cams, X))
        assert np.abs(tri.points - X).max() < 1e-9
        assert tri.inliers.all() and np.nanmax(tri.errors_px) < 1e-6

    def test_gaussian_pixel_noise_gives_error_within_the_expected_bound(self):
        cams, X = _ring(), _points(500, seed=1)
        rng = np.random.default_rng(2)
        sigma = 1.5
        tri = triangulate_points(cams, _observe(cams, X) + rng.normal(0, sigma, (500, 8, 2)))
        err_3d = np.linalg.norm(tri.points - X, axis=1)
        # One pixel is ~1.15 mm at 0.7 m (f = 615 px); 8 views average it down by ~sqrt(8),
        # so the RMS 3-D error should be near 1.5 * 1.15 * sqrt(3 / 8) ~ 1 mm.
        assert np.sqrt(np.mean(err_3d ** 2)) < 2e-3
        # The residuals of an 8-view fit keep ~sqrt(13/16) of the noise's norm.
        assert 0.8 * sigma < np.median(tri.errors_px) < 1.5 * sigma

    def test_gross_outlier_view_is_rejected_and_the_point_stays_accurate(self):
        cams, X = _ring(), _points(200, seed=3)
        pix = _observe(cams, X) + np.random.default_rng(4).normal(0, 1.0, (200, 8, 2))
        pix[:, 5] += [60.0, -45.0]
        tri = triangulate_points(cams, pix)
        assert not tri.inliers[:, 5].any() and tri.inliers[:, [0, 1, 2, 3, 4, 6, 7]].all()
        assert np.median(tri.errors_px[:, 5]) > 50.0
        assert np.linalg.norm(tri.points - X, axis=1).max() < 5e-3
        plain = np.linalg.norm(triangulate_dlt(cams, pix) - X, axis=1)
        assert np.median(plain) > 5e-3  # without rejection the outlier drags the point

    def test_distortion_is_honoured(self):
        cams, X = _ring(), _points(100, seed=5)
        pix = _observe(cams, X)
        tri = triangulate_points(cams, pix)
        pinhole = [CameraModel(c.K, None, c.T_cam_to_world, 640, 480) for c in cams]
        wrong = triangulate_points(pinhole, pix, refine=False)
        assert np.abs(tri.points - X).max() < 1e-9 and np.nanmax(tri.errors_px) < 1e-6
        # Ignoring the lens leaves sub-pixel to pixel residuals and millimetre errors.
        assert np.nanmedian(wrong.errors_px) > 0.3
        assert np.abs(wrong.points - X).max() > 1e-3

    def test_refinement_lowers_the_pixel_error_of_the_linear_estimate(self):
        cams, X = _ring(5), _points(200, seed=6)
        pix = _observe(cams, X) + np.random.default_rng(7).normal(0, 3.0, (200, 5, 2))
        linear = triangulate_points(cams, pix, refine=False)
        refined = triangulate_points(cams, pix)
        assert np.nansum(refined.errors_px ** 2) < np.nansum(linear.errors_px ** 2)

    def test_fewer_than_two_inlier_views_gives_nan(self):
        cams, X = _ring(3), _points(2, seed=8)
        pix = _observe(cams, X)
        pix[0, 1:] = np.nan  # point 0: seen by view 0 only
        # Point 1: views 1 and 2 moved across the (roughly horizontal) epipolar lines, so no
        # two views agree.
        pix[1, 1] += [0.0, 80.0]
        pix[1, 2] -= [0.0, 80.0]
        tri = triangulate_points(cams, pix)
        assert np.isnan(tri.points).all() and not tri.inliers.any()
        assert np.isnan(tri.errors_px[0, 1:]).all()

    def test_repeated_camera_columns_act_as_separate_labels_of_one_view(self):
        cams, X = _ring(4), _points(50, seed=9)
        pix = _observe(cams, X)
        cols = cams + [cams[0]]
        pix5 = np.concatenate([pix, pix[:, :1] + [70.0, 0.0]], axis=1)
        tri = triangulate_points(cols, pix5)
        assert tri.inliers[:, :4].all() and not tri.inliers[:, 4].any()
        assert np.abs(tri.points - X).max() < 1e-9

    def test_wrong_column_count_raises_naming_the_shape(self):
        with pytest.raises(ValueError, match=r"V=3.*\(10, 4, 2\)"):
            triangulate_points(_ring(3), np.zeros((10, 4, 2)))


class TestProjectionJacobian:
    def test_analytic_jacobian_matches_central_differences(self):
        stack = CameraStack.of(_ring(3))
        X = _points(20, seed=10)
        _, _, jac = project_stack(stack, X, jacobian=True)
        h = 1e-6
        plus = [project_stack(stack, X + h * e)[0] for e in np.eye(3)]
        minus = [project_stack(stack, X - h * e)[0] for e in np.eye(3)]
        numeric = np.stack([(p - m) / (2 * h) for p, m in zip(plus, minus, strict=True)], axis=-1)
        assert np.abs(jac - numeric).max() < 1e-4 * np.abs(jac).max()

    def test_matches_camera_model_projection(self):
        cams, X = _ring(3), _points(20, seed=11)
        pix, z, _ = project_stack(CameraStack.of(cams), X)
        assert np.abs(pix - _observe(cams, X)).max() < 1e-9
        assert np.abs(z - np.stack([c.depth_of(X) for c in cams], axis=1)).max() < 1e-12


class TestLeaveOneOutResiduals:
    def test_matches_refitting_without_the_observation(self):
        cams, X = _ring(5), _points(30, seed=12)
        pix = _observe(cams, X) + np.random.default_rng(13).normal(0, 2.0, (30, 5, 2))
        tri = triangulate_points(cams, pix)
        loo = leave_one_out_residuals(cams, pix, tri.points, tri.inliers)
        for v in range(5):
            rest = [c for i, c in enumerate(cams) if i != v]
            refit = triangulate_points(rest, np.delete(pix, v, axis=1)).points
            exact = pix[:, v] - cams[v].project(refit)
            assert np.abs(loo[:, v] - exact).max() < 0.05  # px; linearisation only

    def test_is_larger_than_the_in_sample_residual(self):
        cams, X = _ring(4), _points(200, seed=14)
        pix = _observe(cams, X) + np.random.default_rng(15).normal(0, 2.0, (200, 4, 2))
        tri = triangulate_points(cams, pix)
        loo = np.linalg.norm(leave_one_out_residuals(cams, pix, tri.points, tri.inliers), axis=-1)
        assert np.nanmedian(loo) > 1.1 * np.nanmedian(tri.errors_px)

    def test_nan_where_removing_the_observation_leaves_one_view(self):
        cams, X = _ring(2), _points(5, seed=16)
        pix = _observe(cams, X)
        tri = triangulate_points(cams, pix)
        loo = leave_one_out_residuals(cams, pix, tri.points, tri.inliers)
        assert np.isnan(loo).all()
