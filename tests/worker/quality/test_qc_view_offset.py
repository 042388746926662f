"""worker.quality.view_offset and its use in the hand consensus: a camera whose calibration is off
is reported as the camera's and not charged to its careful workers, while bad work in that very
view is still caught."""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.quality.test_qc_consensus import (
    camera_ring,
    make_label,
    moving_hand,
    truth_pixels,
)
from worker.geometry.cameras import CameraModel
from worker.geometry.transforms import axis_angle_to_matrix
from worker.quality.consensus import score_hand
from worker.quality.view_offset import MIN_OFFSET_PX, fit_view_offset

CENTRE = np.array([320.0, 240.0])


def _similarity(xy: np.ndarray, deg: float, scale: float, shift: tuple[float, float]
                ) -> np.ndarray:
    c, s = np.cos(np.radians(deg)) * scale, np.sin(np.radians(deg)) * scale
    return CENTRE + (xy - CENTRE) @ np.array([[c, -s], [s, c]]).T + np.array(shift)


class TestFitViewOffset:
    def test_recovers_a_camera_wide_similarity_under_careful_noise(self) -> None:
        rng = np.random.default_rng(0)
        ref = rng.uniform([200, 150], [450, 350], (600, 2))
        obs = _similarity(ref, 0.4, 1.004, (4.0, -3.0)) + rng.normal(0, 2.0, ref.shape)
        fit = fit_view_offset(2, [(ref, obs)], CENTRE)
        assert fit.applied and fit.labels == 1
        assert fit.rotation_deg == pytest.approx(0.4, abs=0.05)
        assert fit.scale == pytest.approx(1.004, abs=0.004)
        back = fit.correct(_similarity(ref, 0.4, 1.004, (4.0, -3.0)))
        assert np.abs(back - ref).max() < 1.0

    def test_a_sound_camera_is_left_alone(self) -> None:
        rng = np.random.default_rng(1)
        ref = rng.uniform([200, 150], [450, 350], (600, 2))
        fit = fit_view_offset(0, [(ref, ref + rng.normal(0, 2.0, ref.shape))], CENTRE)
        assert not fit.applied and fit.offset_px < MIN_OFFSET_PX
        np.testing.assert_array_equal(fit.correct(ref), ref)

    def test_random_or_sloppy_labels_do_not_shape_the_map(self) -> None:
        rng = np.random.default_rng(2)
        ref = rng.uniform([200, 150], [450, 350], (400, 2))
        spam = rng.uniform([0, 0], [640, 480], ref.shape)
        sloppy = ref + np.array([5.0, 0.0]) + rng.normal(0, 8.0, ref.shape)
        assert not fit_view_offset(1, [(ref, spam)], CENTRE).applied
        assert not fit_view_offset(1, [(ref, sloppy)], CENTRE).applied
        careful = _similarity(ref, 0.0, 1.0, (5.0, 0.0)) + rng.normal(0, 2.0, ref.shape)
        both = fit_view_offset(1, [(ref, spam), (ref, careful)], CENTRE)
        assert both.applied and both.labels == 1 and both.seen == 2
        assert both.params[2] == pytest.approx(5.0, abs=0.4)


def _off(cams: list[CameraModel], deg: float, mm: float, seed: int) -> list[CameraModel]:
    """The cameras as a faulty calibration has them: every one but the first turned by ``deg``
    about its centre and moved by ``mm``."""
    rng = np.random.default_rng(seed)
    out = [cams[0]]
    for cam in cams[1:]:
        axis, move = rng.normal(size=3), rng.normal(size=3)
        turn = axis_angle_to_matrix(axis / np.linalg.norm(axis) * np.radians(deg))
        pose = np.array(cam.T_cam_to_world, np.float64)
        pose = np.concatenate([turn @ pose[:, :3], (pose[:, 3] + move / np.linalg.norm(move)
                                                    * mm / 1000.0)[:, None]], axis=1)
        out.append(CameraModel(cam.K, cam.dist, pose, cam.width, cam.height))
    return out


@pytest.fixture(scope="module")
def faulty_scene():
    true_cams = camera_ring()
    truth_xy = truth_pixels(true_cams, moving_hand())
    return _off(true_cams, 0.5, 5.0, seed=3), truth_xy


def test_careful_workers_are_not_charged_for_the_cameras_fault(faulty_scene) -> None:
    cams, truth_xy = faulty_scene
    labels = [make_label(f"careful-{v}", v, truth_xy, "careful", 10 + v) for v in range(8)]
    report = score_hand(cams, labels)
    for qc in report.assignments.values():
        assert qc.metrics["median_error_px"] < 2.5, qc.metrics
        assert qc.metrics["p90_error_px"] < 4.5, qc.metrics
    shifted = [v for v, o in report.camera_offsets.items() if o.applied]
    assert len(shifted) >= 6
    for v in shifted:
        assert report.assignments[f"careful-{v}"].metrics["camera_offset_px"] >= MIN_OFFSET_PX
    # The replay's reference is in the view's own pixels: near where the careful label is.
    ref = report.replay["careful-3"]["reference"]
    ok = np.isfinite(ref).all(axis=-1)
    assert np.median(np.linalg.norm(ref[ok] - truth_xy[3][ok], axis=-1)) < 2.0


def test_a_sound_rig_reports_no_camera_offset() -> None:
    cams = camera_ring()
    truth_xy = truth_pixels(cams, moving_hand())
    labels = [make_label(f"careful-{v}", v, truth_xy, "careful", 20 + v) for v in range(8)]
    report = score_hand(cams, labels)
    assert not any(o.applied for o in report.camera_offsets.values())
    assert not any(report.camera_lags.values())
    assert all("camera_offset_px" not in qc.metrics for qc in report.assignments.values())


@pytest.mark.parametrize("profile", ["sloppy", "lazy", "spammer", "swapper"])
def test_bad_work_in_a_faulty_view_is_still_caught(faulty_scene, profile: str) -> None:
    cams, truth_xy = faulty_scene
    labels = [make_label(f"careful-{v}", v, truth_xy, "careful", 30 + v) for v in range(8)]
    labels[4] = make_label("bad", 4, truth_xy, profile, 44)
    report = score_hand(cams, labels)
    bad = report.assignments["bad"]
    if profile == "swapper":
        assert any(sorted(s["fingers"]) == ["little", "ring"] for s in bad.swaps)
    else:
        assert bad.metrics["median_error_px"] > 3.5, bad.metrics
    for key, qc in report.assignments.items():
        if key != "bad":
            assert qc.metrics["median_error_px"] < 2.5, (key, qc.metrics)


def test_a_late_camera_is_found_and_its_careful_worker_not_charged() -> None:
    cams = camera_ring()
    # The hand's motion over 12 frames: ~4 px a frame in view 5, what one frame late shows.
    truth_xy = truth_pixels(cams, moving_hand(12))
    late = truth_xy.copy()
    late[5, 1:] = truth_xy[5, :-1]  # view 5's frame f shows frame f - 1
    labels = [make_label(f"careful-{v}", v, late, "careful", 50 + v) for v in range(8)]
    labels[2] = make_label("lazy", 2, late, "lazy", 60)
    report = score_hand(cams, labels)
    assert report.camera_lags == {v: -1 if v == 5 else 0 for v in range(8)}
    careful = report.assignments["careful-5"]
    assert careful.metrics["camera_lag_frames"] == -1.0
    assert careful.metrics["median_error_px"] < 2.5, careful.metrics
    assert report.assignments["lazy"].metrics["median_error_px"] > 3.5
    # The replay is in the view's own frames: frame f's reference is where frame f - 1 was.
    ref = report.replay["careful-5"]["reference"]
    ok = np.isfinite(ref[1:-1]).all(axis=-1)
    assert np.median(np.linalg.norm(ref[1:-1][ok] - late[5, 1:-1][ok], axis=-1)) < 2.0


@pytest.mark.parametrize("seed", [3, 7, 11])
def test_four_views_three_of_them_off_charge_no_careful_worker(seed: int) -> None:
    # With every camera but the first off, each view's references come mostly from other
    # faulty views: the maps are fitted again once those are corrected.
    true_cams = camera_ring(4)
    truth_xy = truth_pixels(true_cams, moving_hand())
    cams = _off(true_cams, 0.5, 5.0, seed=seed)
    labels = [make_label(f"careful-{v}", v, truth_xy, "careful", 70 + v) for v in range(4)]
    report = score_hand(cams, labels)
    for qc in report.assignments.values():
        assert qc.metrics["median_error_px"] < 2.5, qc.metrics
        assert qc.metrics["p90_error_px"] < 4.5, qc.metrics


@pytest.mark.parametrize("profile", ["sloppy", "lazy"])
def test_four_views_three_of_them_off_still_catch_bad_work(profile: str) -> None:
    true_cams = camera_ring(4)
    truth_xy = truth_pixels(true_cams, moving_hand())
    cams = _off(true_cams, 0.5, 5.0, seed=3)
    labels = [make_label(f"careful-{v}", v, truth_xy, "careful", 80 + v) for v in range(4)]
    labels[2] = make_label("bad", 2, truth_xy, profile, 90)
    report = score_hand(cams, labels)
    assert report.assignments["bad"].metrics["median_error_px"] > 3.5, \
        report.assignments["bad"].metrics
