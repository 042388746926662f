"""worker.quality.consensus: robust hand consensus and per-assignment metrics.

The scene: a ring of 8 calibrated cameras around a moving 21-joint hand (fingers 2 cm apart),
labelled by the simulated annotator profiles (worker.synth.annotators) through the same
keyframes and interpolation as the annotation page. The helpers here are shared with the swap
and decision tests.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at
from worker.quality.consensus import score_hand
from worker.quality.hand_report import HandReport
from worker.quality.view_labels import ViewLabels
from worker.synth.annotators import annotate
from worker.tracks.interpolate import dense_track

WIDTH, HEIGHT = 640, 480
K = intrinsics_matrix(615.0, 615.0, 320.0, 240.0)
DIST = np.array([0.05, -0.08, 0.001, -0.0005, 0.01])
FRAMES = 36


def camera_ring(views: int = 8) -> list[CameraModel]:
    """Cameras 0.7 m around the origin at two heights, looking at it."""
    cams = []
    for i, a in enumerate(np.linspace(0.0, 2.0 * np.pi, views, endpoint=False)):
        eye = np.array([0.7 * np.cos(a), 0.7 * np.sin(a), 0.3 + 0.15 * (i % 2)])
        cams.append(CameraModel(K, DIST, look_at(eye, np.zeros(3), np.array([0, 0, 1.0])),
                                WIDTH, HEIGHT))
    return cams


def moving_hand(frames: int = FRAMES) -> np.ndarray:
    """(F, 21, 3) world metres: a hand drifting and turning, fingers 2 cm apart, curling."""
    t = np.linspace(0.0, 1.0, frames)
    out = np.empty((frames, 21, 3))
    for f in range(frames):
        yaw = 0.8 * t[f]
        rot = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
        wrist = np.array([0.06 * t[f] - 0.03, 0.02 * np.sin(3 * t[f]), 0.03 * t[f]])
        local = [np.array([0.0, -0.06, 0.0])]
        for finger in range(5):
            base = np.array([0.02 * (finger - 2), 0.0, 0.0])
            curl = 0.4 + 0.8 * t[f] * (finger + 1) / 5
            for k in range(4):
                angle = curl * k / 3
                local.append(base + 0.022 * k * np.array([0.0, np.cos(angle), -np.sin(angle)]))
        out[f] = wrist + np.stack(local) @ rot.T
    return out


def truth_pixels(cams: list[CameraModel], joints: np.ndarray) -> np.ndarray:
    """(V, F, 21, 2) true pixels of every view."""
    return np.stack([c.project(joints) for c in cams])


def make_label(key: str, view: int, truth_xy: np.ndarray, profile: str, seed: int) -> ViewLabels:
    """A simulated worker's labels of one view (every joint truly visible)."""
    vis = np.ones(truth_xy.shape[1:3], bool)
    work = annotate(truth_xy[view], vis, (WIDTH, HEIGHT), profile, np.random.default_rng(seed))
    dense = [dense_track(track, truth_xy.shape[1]) for track in work.tracks]
    return ViewLabels(key=key, view=view, xy=np.stack([d.xy for d in dense], axis=1),
                      visible=np.stack([d.visible for d in dense], axis=1), working_time_s=120.0)


def careful_pool(cams, truth_xy, seed: int = 0) -> list[ViewLabels]:
    return [make_label(f"careful-{v}", v, truth_xy, "careful", seed + v) for v in range(len(cams))]


@pytest.fixture(scope="module")
def scene():
    cams = camera_ring()
    joints = moving_hand()
    return cams, joints, truth_pixels(cams, joints)


@pytest.fixture(scope="module")
def mixed_report(scene) -> tuple[HandReport, np.ndarray]:
    """Careful labels of every view plus a spammer, a swapper and a lazy worker."""
    cams, joints, truth_xy = scene
    labels = careful_pool(cams, truth_xy) + [
        make_label("spammer", 1, truth_xy, "spammer", 101),
        make_label("swapper", 2, truth_xy, "swapper", 102),
        make_label("lazy", 3, truth_xy, "lazy", 103)]
    return score_hand(cams, labels), joints


class TestConsensus:
    def test_careful_labels_give_a_millimetre_consensus_and_clean_metrics(self, scene):
        cams, joints, truth_xy = scene
        report = score_hand(cams, careful_pool(cams, truth_xy))
        err = np.linalg.norm(report.consensus - joints, axis=-1)
        assert np.nanmedian(err) < 2e-3 and np.nanmax(err) < 8e-3
        assert not report.provisional and (report.support == 8).mean() > 0.95
        for qc in report.assignments.values():
            assert 1.5 < qc.metrics["median_error_px"] < 3.5
            assert qc.metrics["outlier_fraction"] < 0.01
            assert 0.8 < qc.metrics["motion_ratio"] < 1.4
            assert qc.metrics["completeness"] == 1.0 and not qc.swaps and not qc.provisional

    def test_spammer_swapper_and_lazy_worker_do_not_drag_the_consensus(self, mixed_report):
        report, joints = mixed_report
        err = np.linalg.norm(report.consensus - joints, axis=-1)
        assert np.nanmedian(err) < 2e-3 and np.nanmax(err) < 8e-3

    def test_bad_workers_show_in_their_metrics(self, mixed_report):
        report, _ = mixed_report
        spam, lazy = report.assignments["spammer"], report.assignments["lazy"]
        assert spam.metrics["outlier_fraction"] > 0.9 and spam.metrics["median_error_px"] > 50
        assert spam.metrics["motion_ratio"] > 3.0
        assert lazy.metrics["motion_ratio"] < 0.05
        careful = report.assignments["careful-1"].metrics
        assert careful["outlier_fraction"] < 0.01 and careful["median_error_px"] < 3.5

    def test_label_is_scored_against_a_consensus_without_it(self, scene):
        # With three views an in-sample residual would shrink by about a half; the
        # leave-one-out error keeps the annotator's noise: raw, it grows by how loosely the
        # two other views fix the point (2 px per axis, Rayleigh median 2.35 px plus that).
        cams, _joints, truth_xy = scene
        labels = careful_pool(cams[:3], truth_xy)
        report = score_hand(cams[:3], labels)
        raw = [qc.metrics["raw_median_error_px"] for qc in report.assignments.values()]
        assert all(1.8 < m < 4.0 for m in raw)

    def test_careful_errors_read_the_same_at_three_views_as_at_eight(self, scene):
        # Normalised to the reference's spread, a careful label scores alike whether two or
        # seven other views fix its points; raw errors grow as the support shrinks.
        cams, _joints, truth_xy = scene
        few = score_hand(cams[:3], careful_pool(cams[:3], truth_xy))
        many = score_hand(cams, careful_pool(cams, truth_xy))

        def medians(report: HandReport, name: str) -> float:
            return float(np.median([qc.metrics[name] for qc in report.assignments.values()]))

        assert medians(few, "raw_median_error_px") > 1.2 * medians(many, "raw_median_error_px")
        assert abs(medians(few, "median_error_px") - medians(many, "median_error_px")) < 0.3
        assert all(1.2 < qc.metrics["median_error_px"] < 2.5
                   for qc in few.assignments.values())

    def test_two_views_make_a_provisional_report(self, scene):
        cams, _joints, truth_xy = scene
        report = score_hand(cams, careful_pool(cams, truth_xy)[:2])
        assert report.provisional
        assert all(qc.provisional for qc in report.assignments.values())

    def test_per_joint_and_per_frame_errors_locate_a_bad_joint(self, scene):
        cams, _joints, truth_xy = scene
        labels = careful_pool(cams, truth_xy)
        bad = labels[4]
        bad.xy = bad.xy.copy()
        bad.xy[8:30, 8] += [25.0, 0.0]  # the index tip 25 px off in frames 8-29
        qc = score_hand(cams, labels).assignments[bad.key]
        assert len(qc.per_joint) == 21 and len(qc.per_frame) == FRAMES
        assert qc.per_joint[8] > 10 and max(v for i, v in enumerate(qc.per_joint) if i != 8) < 5
        issue = qc.issues[0]
        assert issue["point"] == 8 and issue["frames"] == [8, 29] and issue["views"] == 7
        assert 20 < issue["error_px"] < 30

    def test_report_is_json_friendly(self, mixed_report):
        report, _ = mixed_report
        text = json.dumps(report.to_dict(), allow_nan=False)
        assert '"swapper"' in text and "NaN" not in text


class TestDepthVisibility:
    def _depth(self, cams, joints, offset_m: float) -> dict[int, np.ndarray]:
        """Depth maps reading every pixel at the hand's mean depth plus ``offset_m``."""
        out = {}
        for v, cam in enumerate(cams):
            z = cam.depth_of(joints).mean(axis=1)  # (F,)
            mm = np.round((z + offset_m) * 1000.0).astype(np.uint16)
            out[v] = np.broadcast_to(mm[:, None, None], (len(z), HEIGHT, WIDTH)).copy()
        return out

    def test_points_marked_occluded_on_the_visible_surface_are_counted(self, scene):
        cams, joints, truth_xy = scene
        labels = careful_pool(cams, truth_xy)
        labels[0].visible = labels[0].visible.copy()
        labels[0].visible[:18] = False  # half the clip marked occluded
        report = score_hand(cams, labels, self._depth(cams, joints, 0.5))  # wall far behind
        m0, m1 = report.assignments["careful-0"].metrics, report.assignments["careful-1"].metrics
        assert 0.45 < m0["occluded_on_surface"] < 0.55 and m1["occluded_on_surface"] == 0.0
        assert m0["visible_behind_surface"] is None

    def test_points_marked_visible_behind_a_near_surface_are_counted(self, scene):
        cams, joints, truth_xy = scene
        report = score_hand(cams, careful_pool(cams, truth_xy), self._depth(cams, joints, -0.2))
        m = report.assignments["careful-3"].metrics
        assert m["visible_behind_surface"] == 1.0 and m["visibility_disagreement"] == 1.0

    def test_without_depth_visibility_metrics_are_none(self, mixed_report):
        report, _ = mixed_report
        assert report.assignments["careful-0"].metrics["visibility_disagreement"] is None


class TestInputChecks:
    def test_label_shape_mismatch_names_the_label_and_shapes(self, scene):
        cams, _joints, truth_xy = scene
        labels = careful_pool(cams, truth_xy)[:3]
        labels[2] = ViewLabels("short", 2, labels[2].xy[:10], labels[2].visible[:10])
        with pytest.raises(ValueError, match=r"'short'.*\(10, 21, 2\)"):
            score_hand(cams, labels)

    def test_view_out_of_range_and_unknown_option_raise(self, scene):
        cams, _joints, truth_xy = scene
        labels = careful_pool(cams, truth_xy)[:3]
        with pytest.raises(ValueError, match="view 9"):
            score_hand(cams, labels[:2] + [ViewLabels("x", 9, labels[2].xy, labels[2].visible)])
        with pytest.raises(ValueError, match="outlier_pixels"):
            score_hand(cams, labels, outlier_pixels=3.0)
