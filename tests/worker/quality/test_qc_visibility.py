"""The depth check of hand visibility flags (worker.assist.visibility.surface_check and
depth_visibility) against the synthetic capture's ground truth (worker.synth.annotators
hand_visibility: a joint is occluded only where something other than the hand covers it).

The capture: seed 5, 6 views x 72 frames at 320x240, a hand grasping one object; its own
rendered depth maps (sensor noise, dropouts). Labels come from the simulated annotators through
the same keyframes and interpolation as the annotation page.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from backend.captures.layout import find_sequence_dirs, read_sequence
from worker.assist.visibility import OWN_SURFACE_M, distance_to_hand, surface_check
from worker.formats import dexycb
from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at
from worker.quality.consensus import score_hand
from worker.quality.metrics import depth_visibility
from worker.synth.annotators import hand_visibility
from worker.synth.qc_evaluation import simulated_labels


class CaptureTruth:
    """Cameras, true joints (world), true visibility and depth maps of every view."""

    def __init__(self, root: Path) -> None:
        plan = read_sequence(find_sequence_dirs(root)[0])
        self.cameras: list[CameraModel] = []
        xy, visible, self.depth, world = [], [], {}, []
        for v, cam in enumerate(plan.cameras):
            ext = np.asarray(cam.extrinsics, float)
            self.cameras.append(CameraModel(intrinsics_matrix(cam.fx, cam.fy, cam.ppx, cam.ppy),
                                            np.asarray(cam.distortion), ext, cam.width,
                                            cam.height))
            folder = plan.seq_dir / cam.serial
            j2, j3, seg, depth = [], [], [], []
            for f in range(plan.num_frames):
                with np.load(folder / dexycb.labels_file(f)) as labels:
                    j2.append(labels[dexycb.JOINT_2D][0].astype(float))
                    j3.append(labels["joint_3d"][0].astype(float))
                    seg.append(labels[dexycb.SEG])
                depth.append(cv2.imread(str(folder / dexycb.depth_file(f)),
                                        cv2.IMREAD_UNCHANGED))
            xy.append(np.stack(j2))
            visible.append(hand_visibility(np.stack(j2), np.stack(seg)))
            self.depth[v] = np.stack(depth)
            world.append(np.stack(j3) @ ext[:, :3].T + ext[:, 3])
        self.xy, self.visible = np.stack(xy), np.stack(visible)
        self.joints = np.mean(world, axis=0)


@pytest.fixture(scope="module")
def truth(visibility_capture: Path) -> CaptureTruth:
    return CaptureTruth(visibility_capture)


def _checks(truth: CaptureTruth) -> list:
    return [surface_check(cam, truth.joints, truth.depth[v])
            for v, cam in enumerate(truth.cameras)]


class TestSurfaceCheckAgainstTruth:
    """The check at the true joints. (At 320x240 a joint at an object's outline often has the
    object at its pixel and hand pixels within the truth's 2 px: those few are visible in truth
    and judged hidden.)"""

    def test_scene_has_self_occlusion_and_object_occlusion(self, truth):
        # With the hand's own surface counted as a cover, the depth map finds many more joints
        # covered than the truth has occluded: the hand covers its own joints.
        covered = sum(int(surface_check(cam, truth.joints, truth.depth[v],
                                        own_surface_m=0.0).hidden.sum())
                      for v, cam in enumerate(truth.cameras))
        truly_hidden = int((~truth.visible).sum())
        assert truly_hidden > 200 and covered > 2 * truly_hidden

    def test_points_judged_hidden_are_occluded_in_truth(self, truth):
        hidden = np.stack([c.hidden for c in _checks(truth)])
        assert hidden.sum() > 200
        assert truth.visible[hidden].mean() < 0.25

    def test_points_judged_on_the_surface_are_visible_in_truth(self, truth):
        on_surface = np.stack([c.on_surface for c in _checks(truth)])
        assert on_surface.sum() > 0.5 * on_surface.size
        assert (~truth.visible[on_surface]).mean() < 0.01

    def test_most_truly_occluded_points_are_judged_hidden(self, truth):
        hidden = np.stack([c.hidden for c in _checks(truth)])
        assert hidden[~truth.visible].mean() > 0.6

    def test_all_visible_flags_are_all_caught_behind_the_surface(self, truth):
        rates = [depth_visibility(np.ones_like(truth.visible[v]), c)["visible_behind_surface"]
                 for v, c in enumerate(_checks(truth))]
        assert any(r is not None for r in rates)
        assert all(r == 1.0 for r in rates if r is not None)


@pytest.fixture(scope="module")
def scored(truth: CaptureTruth) -> dict[str, list[tuple[dict, float]]]:
    """Careful, occluder and spammer workers on every view, scored together by the consensus
    (not the true joints): per profile, each label's metrics and its true disagreement (share
    of (frame, joint) flags that differ from the truth)."""
    plan = [(v, p) for v in range(len(truth.cameras)) for p in ("careful", "occluder", "spammer")]
    cam = truth.cameras[0]
    labels, profiles = simulated_labels(truth.xy, truth.visible, (cam.width, cam.height), plan,
                                        np.random.default_rng(3))
    report = score_hand(truth.cameras, labels, truth.depth)
    out: dict[str, list[tuple[dict, float]]] = {}
    for lab in labels:
        true = float((lab.visible != truth.visible[lab.view]).mean())
        out.setdefault(profiles[lab.key], []).append((report.assignments[lab.key].metrics, true))
    return out


def _median(rows: list[tuple[dict, float]], name: str) -> float:
    return float(np.median([m[name] for m, _ in rows if m[name] is not None]))


class TestScoredWorkersAgainstTruth:
    def test_careful_workers_hardly_disagree_with_the_depth_map(self, scored):
        careful = scored["careful"]
        assert all(true == 0.0 for _, true in careful)
        for metrics, _ in careful:
            assert metrics["visibility_disagreement"] < 0.06, metrics
            assert metrics["occluded_on_surface"] < 0.02, metrics
        assert _median(careful, "visibility_disagreement") < 0.03
        # Counted over the few points something covers (tens per view), so it moves in steps.
        assert _median(careful, "visible_behind_surface") < 0.5

    def test_occluders_disagree_as_much_as_they_do_with_the_truth(self, scored):
        for metrics, true in scored["occluder"]:
            assert true > 0.4 and metrics["occluded_on_surface"] > 0.4
            assert metrics["visibility_disagreement"] == pytest.approx(true, abs=0.08), metrics

    def test_random_clicks_marked_visible_disagree_only_where_something_covers(self, scored):
        # Every flag is "visible": wrong only where the truth has the joint occluded (a few
        # percent of the clip; the metric counts over the judged points only).
        spammers = scored["spammer"]
        assert np.mean([true for _, true in spammers]) < 0.1
        assert _median(spammers, "visibility_disagreement") < 0.1
        for metrics, _ in spammers:
            assert metrics["visible_behind_surface"] in (None, 1.0)
            assert metrics["occluded_on_surface"] == 0.0


class TestOwnSurface:
    """A hand in front of a camera; a depth map holding a chosen surface at one joint."""

    @staticmethod
    def _scene() -> tuple[CameraModel, np.ndarray]:
        cam = CameraModel(intrinsics_matrix(300.0, 300.0, 160.0, 120.0), None,
                          look_at(np.array([0.0, 0.0, -0.6]), np.zeros(3),
                                  np.array([0.0, -1.0, 0.0])), 320, 240)
        joints = np.zeros((1, 21, 3))
        for finger in range(5):
            for k in range(4):
                joints[0, 1 + 4 * finger + k] = [0.02 * (finger - 2), 0.03 + 0.025 * k, 0.0]
        joints[0, 0] = [0.0, -0.05, 0.0]
        return cam, joints

    @staticmethod
    def _depth_at(cam: CameraModel, joints: np.ndarray, joint: int,
                  surface_world: np.ndarray) -> np.ndarray:
        """A depth map reading 1 m everywhere but around ``joint``'s pixel, where it reads the
        depth of ``surface_world``."""
        depth = np.full((1, cam.height, cam.width), 1000, np.uint16)
        col, row = np.rint(cam.project(joints[0, joint])).astype(int)
        depth[0, row - 2:row + 3, col - 2:col + 3] = round(
            float(cam.depth_of(surface_world)) * 1000)
        return depth

    def test_a_finger_in_front_of_a_joint_hides_nothing(self):
        cam, joints = self._scene()
        # The middle fingertip curled 6 cm towards the camera, right in front of its knuckle:
        # the camera sees the finger's skin 1 cm in front of the tip joint.
        joints[0, 12] = joints[0, 9] + [0.0, 0.0, -0.06]
        skin = joints[0, 12] + [0.0, 0.0, -0.01]
        depth = self._depth_at(cam, joints, 9, skin)
        check = surface_check(cam, joints, depth)
        assert not check.hidden[0, 9] and not check.on_surface[0, 9]
        assert check.on_surface[0, 1:9].all()
        covered = surface_check(cam, joints, depth, own_surface_m=0.0)
        assert covered.hidden[0, 9]

    def test_an_object_in_front_of_a_joint_hides_it(self):
        cam, joints = self._scene()
        wall = joints[0, 9] + [0.0, 0.0, -0.08]  # 8 cm in front, 3 cm+ from any bone
        check = surface_check(cam, joints, self._depth_at(cam, joints, 9, wall))
        assert check.hidden[0, 9] and check.hidden.sum() == 1

    def test_distance_to_hand_measures_bones_and_palm(self):
        _, joints = self._scene()
        points = np.array([[joints[0, 6] + [0.0, 0.0, 0.012],    # above a finger bone
                            [0.0, -0.01, 0.015],                  # above the palm
                            [0.3, 0.3, 0.3],
                            joints[0, 20]]])
        d = distance_to_hand(points, joints)
        assert d[0] == pytest.approx([0.012, 0.015, d[0, 2], 0.0], abs=1e-9)
        assert d[0, 2] > 0.2 and d[0, 1] < OWN_SURFACE_M
        missing = joints.copy()
        missing[0, :] = np.nan
        assert np.isinf(distance_to_hand(points, missing)).all()

    def test_bad_shapes_are_refused_with_their_shape(self):
        _, joints = self._scene()
        with pytest.raises(ValueError, match=r"got \(1, 4\)"):
            distance_to_hand(np.zeros((1, 4)), joints)
