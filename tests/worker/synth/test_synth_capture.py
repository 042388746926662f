"""worker.synth.generate_capture: the DexYCB layout and the consistency of its ground truth."""

from __future__ import annotations

import hashlib
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
import yaml

from worker.formats.dexycb import HAND_SEG_VALUE, YCB_CLASSES
from worker.geometry import (
    intrinsics_matrix,
    invert_pose,
    pixels_to_rays,
    project_camera_points,
    project_points,
    quaternion_to_matrix,
    read_mesh,
    world_to_camera,
)
from worker.hand import HandLayer, builtin_hand_model
from worker.synth import SynthSummary, generate_capture
from worker.synth.scene import object_sdf
from worker.synth.shapes import CATALOGUE

SMALL = {"seed": 3, "frames": 6, "views": 3, "width": 320, "height": 240}


@pytest.fixture(scope="module")
def capture(tmp_path_factory) -> SynthSummary:
    return generate_capture(tmp_path_factory.mktemp("cap") / "a", workers=1, **SMALL)


@pytest.fixture(scope="module")
def layer() -> HandLayer:
    return HandLayer(builtin_hand_model("right"))


class Capture:
    """Readers for a written capture."""

    def __init__(self, summary: SynthSummary):
        self.root = summary.root
        self.seq = summary.root / summary.subject / summary.sequence
        self.meta = yaml.safe_load((self.seq / "meta.yml").read_text())
        calib = self.root / "calibration"
        self.extrinsics = yaml.safe_load(
            (calib / f"extrinsics_{self.meta['extrinsics']}" / "extrinsics.yml").read_text())
        mano = calib / f"mano_{self.meta['mano_calib'][0]}" / "mano.yml"
        self.betas = np.array(yaml.safe_load(mano.read_text())["betas"])
        self.pose = np.load(self.seq / "pose.npz")

    def intrinsics(self, serial: str, size: str = "320x240") -> dict:
        path = self.root / "calibration" / "intrinsics" / f"{serial}_{size}.yml"
        return yaml.safe_load(path.read_text())

    def camera(self, serial: str):
        color = self.intrinsics(serial)["color"]
        K = intrinsics_matrix(color["fx"], color["fy"], color["ppx"], color["ppy"])
        T = np.array(self.extrinsics["extrinsics"][serial], dtype=np.float64).reshape(3, 4)
        return K, np.array(color["coeffs"]), T

    def labels(self, serial: str, frame: int):
        return np.load(self.seq / serial / f"labels_{frame:06d}.npz")


def _hand(layer: HandLayer, pose_m: np.ndarray, betas: np.ndarray):
    out = layer.from_pose_m(torch.as_tensor(pose_m, dtype=torch.float64),
                            torch.as_tensor(betas, dtype=torch.float64))
    return out.vertices.numpy(), out.joints.numpy()


def _digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


class TestLayout:
    def test_metadata_and_calibration_have_the_dexycb_fields(self, capture):
        cap = Capture(capture)
        assert cap.meta["serials"] == capture.serials and cap.meta["num_frames"] == 6
        assert cap.meta["ycb_ids"] == capture.ycb_ids
        assert 0 <= cap.meta["ycb_grasp_ind"] < len(capture.ycb_ids)
        assert cap.meta["mano_sides"] == ["right"] and len(cap.meta["mano_calib"]) == 1
        assert cap.extrinsics["master"] == capture.serials[0]
        assert set(cap.extrinsics["extrinsics"]) == {*capture.serials, "apriltag"}
        identity = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]
        assert cap.extrinsics["extrinsics"][capture.serials[0]] == identity
        assert cap.betas.shape == (10,)
        for serial in capture.serials:
            assert len(serial) == 12 and serial.isdigit()
            intr = cap.intrinsics(serial)
            assert intr["color"] == intr["depth"]
            assert set(intr["color"]) == {"fx", "fy", "ppx", "ppy", "width", "height", "coeffs"}
            assert len(intr["color"]["coeffs"]) == 5
            T = np.array(cap.extrinsics["extrinsics"][serial]).reshape(3, 4)
            np.testing.assert_allclose(T[:, :3] @ T[:, :3].T, np.eye(3), atol=1e-12)

    def test_pose_npz_shapes(self, capture):
        pose = Capture(capture).pose
        k = len(capture.ycb_ids)
        assert pose["pose_y"].shape == (6, k, 7) and pose["pose_y"].dtype == np.float32
        assert pose["pose_m"].shape == (6, 1, 51) and pose["pose_m"].dtype == np.float32

    def test_every_frame_has_color_depth_and_labels_of_the_right_kind(self, capture):
        cap = Capture(capture)
        k = len(capture.ycb_ids)
        for serial in capture.serials:
            names = sorted(p.name for p in (cap.seq / serial).iterdir())
            assert len(names) == 18
            for frame in (0, 5):
                color = cv2.imread(str(cap.seq / serial / f"color_{frame:06d}.jpg"))
                depth = cv2.imread(
                    str(cap.seq / serial / f"aligned_depth_to_color_{frame:06d}.png"),
                    cv2.IMREAD_UNCHANGED)
                assert color.shape == (240, 320, 3) and depth.shape == (240, 320)
                assert depth.dtype == np.uint16
                labels = cap.labels(serial, frame)
                assert labels["seg"].shape == (240, 320) and labels["seg"].dtype == np.uint8
                assert labels["pose_y"].shape == (k, 3, 4)
                assert labels["pose_m"].shape == (1, 51)
                assert labels["joint_3d"].shape == (1, 21, 3)
                assert labels["joint_2d"].shape == (1, 21, 2)

    def test_object_models_are_textured_meshes(self, capture):
        for ycb_id in capture.ycb_ids:
            folder = capture.root / "models" / YCB_CLASSES[ycb_id]
            mesh = read_mesh(folder / "textured_simple.obj")
            assert mesh.uvs is not None and len(mesh.faces) >= 12
            assert "map_Kd texture_map.png" in (folder / "textured_simple.obj.mtl").read_text()
            assert cv2.imread(str(folder / "texture_map.png")) is not None
            np.testing.assert_allclose(np.ptp(mesh.vertices, axis=0),
                                       2 * CATALOGUE[ycb_id].half_extents, atol=1e-3)

    def test_refuses_to_overwrite_a_non_empty_folder(self, capture):
        with pytest.raises(FileExistsError):
            generate_capture(capture.root, frames=2, views=1)

    @pytest.mark.parametrize(("bad", "message"), [
        ({"frames": 1}, "frames must be"), ({"views": 0}, "views must be"),
        ({"objects": 0}, "objects must be"), ({"seed": -1}, "seed must be"),
    ])
    def test_rejects_bad_arguments(self, tmp_path, bad, message):
        with pytest.raises(ValueError, match=message):
            generate_capture(tmp_path / "x", **bad)
        assert not (tmp_path / "x").exists()


class TestGroundTruth:
    def test_joint_2d_is_the_projection_of_joint_3d_and_of_world_joints(self, capture, layer):
        cap = Capture(capture)
        _, world = _hand(layer, cap.pose["pose_m"][:, 0], cap.betas)
        for serial in capture.serials:
            K, dist, T = cap.camera(serial)
            for frame in range(6):
                labels = cap.labels(serial, frame)
                joint_2d = labels["joint_2d"][0]
                cam_joints = labels["joint_3d"][0].astype(np.float64)
                assert np.abs(project_camera_points(cam_joints, K, dist) - joint_2d).max() < 0.01
                assert np.abs(project_points(world[frame], K, T, dist) - joint_2d).max() < 0.01
                assert np.abs(world_to_camera(world[frame], T) - cam_joints).max() < 1e-4

    def test_pose_m_in_camera_and_world_frames_reproduces_joint_3d(self, capture, layer):
        cap = Capture(capture)
        for serial in capture.serials:
            _, _, T = cap.camera(serial)
            pose_m = np.stack([cap.labels(serial, f)["pose_m"][0] for f in range(6)])
            joint_3d = np.stack([cap.labels(serial, f)["joint_3d"][0] for f in range(6)])
            _, cam_joints = _hand(layer, pose_m, cap.betas)
            assert np.abs(cam_joints - joint_3d).max() < 1e-4
            _, world = _hand(layer, cap.pose["pose_m"][:, 0], cap.betas)
            assert np.abs(world_to_camera(world, T) - joint_3d).max() < 1e-4

    def test_camera_object_poses_match_world_poses(self, capture):
        cap = Capture(capture)
        pose_y = cap.pose["pose_y"].astype(np.float64)
        rot, trans = quaternion_to_matrix(pose_y[..., :4]), pose_y[..., 4:]
        for serial in capture.serials:
            _, _, T = cap.camera(serial)
            w2c = invert_pose(T)
            for frame in range(6):
                cam = cap.labels(serial, frame)["pose_y"].astype(np.float64)
                np.testing.assert_allclose(cam[:, :, :3], w2c[:, :3] @ rot[frame], atol=1e-5)
                np.testing.assert_allclose(cam[:, :, 3], trans[frame] @ w2c[:, :3].T + w2c[:, 3],
                                           atol=1e-5)

    def test_grasped_object_is_lifted_and_the_others_stay(self, capture):
        cap = Capture(capture)
        pose_y, grasped = cap.pose["pose_y"], cap.meta["ycb_grasp_ind"]
        moved = np.linalg.norm(pose_y[-1, :, 4:] - pose_y[0, :, 4:], axis=1)
        assert moved[grasped] > 0.08
        assert np.all(np.delete(moved, grasped) == 0.0)

    def test_depth_and_seg_agree_with_object_and_hand_geometry(self, capture, layer):
        cap = Capture(capture)
        frame, serial = 4, capture.serials[1]
        K, dist, _ = cap.camera(serial)
        labels = cap.labels(serial, frame)
        depth = cv2.imread(str(cap.seq / serial / f"aligned_depth_to_color_{frame:06d}.png"),
                           cv2.IMREAD_UNCHANGED).astype(np.float64) / 1000.0
        ys, xs = np.mgrid[0:240, 0:320]
        rays = pixels_to_rays(np.stack([xs, ys], -1).astype(np.float64), K, dist)
        points = rays * depth[..., None]
        valid = depth > 0
        for k, ycb_id in enumerate(capture.ycb_ids):
            mask = valid & (labels["seg"] == ycb_id)
            if mask.sum() < 20:
                continue
            pose = labels["pose_y"][k].astype(np.float64)
            local = (points[mask] - pose[:, 3]) @ pose[:, :3]
            assert np.median(np.abs(object_sdf(CATALOGUE[ycb_id], local))) < 0.004
        hand = valid & (labels["seg"] == HAND_SEG_VALUE)
        assert hand.sum() > 50
        vertices, _ = _hand(layer, labels["pose_m"].astype(np.float64), cap.betas)
        nearest = np.linalg.norm(points[hand][:, None] - vertices[0][None], axis=2).min(axis=1)
        assert np.median(nearest) < 0.006


class TestSensor:
    def test_seg_shows_the_hand_and_the_grasped_object(self, capture):
        cap = Capture(capture)
        grasped = capture.ycb_ids[cap.meta["ycb_grasp_ind"]]
        seen = set()
        for serial in capture.serials:
            for frame in range(6):
                seen |= set(np.unique(cap.labels(serial, frame)["seg"]).tolist())
        assert {0, HAND_SEG_VALUE, grasped} <= seen
        assert seen <= {0, HAND_SEG_VALUE, *capture.ycb_ids}

    def test_depth_has_holes_on_surfaces_and_noise_on_the_table(self, capture):
        cap = Capture(capture)
        serial, frame = capture.serials[0], 2
        K, dist, _ = cap.camera(serial)
        depth = cv2.imread(str(cap.seq / serial / f"aligned_depth_to_color_{frame:06d}.png"),
                           cv2.IMREAD_UNCHANGED).astype(np.float64) / 1000.0
        seg = cap.labels(serial, frame)["seg"]
        on_objects = seg > 0
        hole_fraction = np.mean(depth[on_objects] == 0)
        assert 0.0 < hole_fraction < 0.3
        # The table is a plane: fit it to the back-projected table pixels; the residual is noise.
        ys, xs = np.nonzero((seg == 0) & (depth > 0))
        rays = pixels_to_rays(np.stack([xs, ys], -1).astype(np.float64), K, dist)
        points = rays * depth[ys, xs, None]
        centred = points - points.mean(axis=0)
        residual = centred @ np.linalg.svd(centred, full_matrices=False)[2][2]
        assert 0.0003 < np.std(residual) < 0.01


class TestDeterminism:
    def test_same_seed_gives_identical_bytes_whatever_the_workers(self, capture, tmp_path):
        again = generate_capture(tmp_path / "b", workers=2, **SMALL)
        assert _digest(again.root) == _digest(capture.root)

    def test_different_seed_gives_different_files(self, capture, tmp_path):
        other = generate_capture(tmp_path / "c", workers=1, **{**SMALL, "seed": 4})
        assert other.serials != capture.serials and other.sequence != capture.sequence
        for suffix in (".jpg", ".png", ".npz", ".yml"):
            ours = {h for name, h in _digest(capture.root).items() if name.endswith(suffix)
                    and "models" not in name}
            theirs = {h for name, h in _digest(other.root).items() if name.endswith(suffix)
                      and "models" not in name}
            assert ours and not ours & theirs, suffix


def test_default_size_capture_matches_a_d415(tmp_path):
    summary = generate_capture(tmp_path / "d", seed=5, frames=2, views=2, workers=1)
    cap = Capture(summary)
    color = cap.intrinsics(summary.serials[0], "640x480")["color"]
    assert (color["width"], color["height"]) == (640, 480)
    assert 590 < color["fx"] < 640 and abs(color["ppx"] - 319.5) < 15
    image = cv2.imread(str(cap.seq / summary.serials[0] / "color_000001.jpg"))
    assert image.shape == (480, 640, 3)
