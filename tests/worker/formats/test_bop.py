"""BOP export: every file of a scene read back and checked against a hand-built scene.

The scene: three boxes seen by a tilted camera; a near box (14) in front of a far one (2), a
hand rectangle over the near one, and a third box (5) cut by the image's right border. A box's
full silhouette is the convex hull of its projected corners, the known answer for the masks.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial import ConvexHull

from worker.formats.bop import (
    BopSceneWriter,
    ObjectModel,
    SceneCamera,
    model_info,
    write_models,
    write_targets,
)
from worker.formats.dexycb import YCB_CLASSES
from worker.geometry.mesh_io import read_mesh
from worker.geometry.transforms import axis_angle_to_matrix, compose_poses, make_pose

WIDTH, HEIGHT = 160, 120
K = np.array([[200.0, 0.0, 79.5], [0.0, 205.0, 61.25], [0.0, 0.0, 1.0]])
T_CAM_TO_WORLD = make_pose(axis_angle_to_matrix(np.array([0.3, -0.2, 0.1])),
                           np.array([0.4, -0.1, 0.9]))
NEAR, FAR, CUT = 14, 2, 5
HALF_SIZES = {NEAR: (0.05, 0.03, 0.04), FAR: (0.08, 0.06, 0.05), CUT: (0.04, 0.04, 0.04)}
# Object-to-camera poses (axis-angle rad, translation m) of image 0; image 3 moves them 2 cm.
CAMERA_POSES = {NEAR: ((0.2, 0.5, 0.1), (0.0, 0.0, 0.6)),
                FAR: ((-0.3, 0.1, 0.4), (0.05, 0.03, 0.9)),
                CUT: ((0.1, 0.1, 0.7), (0.27, -0.02, 0.6))}
HOLES = slice(70, 76)  # depth columns without a measurement


def _box(half: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
                       dtype=np.float64) * half
    faces = ConvexHull(corners).simplices
    return corners, faces


MODELS = {k: ObjectModel(k, *_box(h)) for k, h in HALF_SIZES.items()}


def _object_to_camera(obj_id: int, shift: float) -> np.ndarray:
    aa, t = CAMERA_POSES[obj_id]
    return make_pose(axis_angle_to_matrix(np.array(aa)), np.array(t) + [shift, 0.0, 0.0])


def _hull_mask(obj_id: int, pose_cam: np.ndarray, x0: int, y0: int, w: int, h: int
               ) -> np.ndarray:
    """(h, w) bool: pixel centres (x0 + i, y0 + j) inside the projected box's convex hull."""
    cam = MODELS[obj_id].vertices @ pose_cam[:, :3].T + pose_cam[:, 3]
    uv = cam @ K.T
    uv = uv[:, :2] / uv[:, 2:]
    hull = uv[ConvexHull(uv).vertices]  # counter-clockwise
    ys, xs = np.mgrid[y0:y0 + h, x0:x0 + w].astype(np.float64)
    inside = np.ones((h, w), dtype=bool)
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        inside &= (b[0] - a[0]) * (ys - a[1]) - (b[1] - a[1]) * (xs - a[0]) >= 0
    return inside


def _scene(shift: float) -> dict[str, Any]:
    """One image: poses (camera and world), expected full masks, seg and depth."""
    cam_poses = {k: _object_to_camera(k, shift) for k in (NEAR, FAR, CUT)}
    full = {k: _hull_mask(k, p, 0, 0, WIDTH, HEIGHT) for k, p in cam_poses.items()}
    seg = np.zeros((HEIGHT, WIDTH), np.uint8)
    for obj_id in (FAR, NEAR, CUT):  # far to near
        seg[full[obj_id]] = obj_id
    seg[55:70, 60:90] = 255  # the hand, over the near box
    depth = np.where(seg > 0, 600, 0).astype(np.uint16)
    depth[:, HOLES] = 0
    world = {k: compose_poses(T_CAM_TO_WORLD, p) for k, p in cam_poses.items()}
    return {"cam": cam_poses, "world": world, "full": full, "seg": seg, "depth": depth}


@pytest.fixture(scope="module")
def exported() -> tuple[dict[str, bytes], dict[int, dict[str, Any]]]:
    files: dict[str, bytes] = {}

    def sink(path: str, data: bytes) -> None:
        assert path not in files
        files[path] = data

    scenes = {0: _scene(0.0), 3: _scene(0.02)}
    writer = BopSceneWriter(sink, 7, SceneCamera(K, T_CAM_TO_WORLD, WIDTH, HEIGHT, 1.0),
                            MODELS)
    for im_id, scene in scenes.items():
        writer.add_image(im_id, scene["seg"], [(k, scene["world"][k]) for k in (NEAR, FAR, CUT)],
                         depth=scene["depth"], rgb=b"jpeg bytes")
    writer.close()
    write_models(sink, MODELS.values())
    return files, scenes


def _json(files: dict[str, bytes], name: str) -> dict[str, Any]:
    document: dict[str, Any] = json.loads(files[f"test/000007/{name}.json"])
    return document


def _png(data: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)


class TestBopSceneWriter:
    def test_writes_the_documented_files_with_zero_padded_ids(self, exported: Any) -> None:
        files, _ = exported
        expected = {f"test/000007/{n}.json" for n in ("scene_camera", "scene_gt",
                                                      "scene_gt_info")}
        for im_id in (0, 3):
            expected |= {f"test/000007/depth/{im_id:06d}.png",
                         f"test/000007/rgb/{im_id:06d}.jpg"}
            expected |= {f"test/000007/{kind}/{im_id:06d}_{gt:06d}.png"
                         for kind in ("mask", "mask_visib") for gt in range(3)}
        expected |= {f"models/obj_{k:06d}.ply" for k in MODELS} | {"models/models_info.json"}
        assert set(files) == expected

    def test_scene_camera_holds_k_and_the_world_to_camera_pose_in_mm(self,
                                                                     exported: Any) -> None:
        files, _ = exported
        cameras = _json(files, "scene_camera")
        assert set(cameras) == {"0", "3"}
        for entry in cameras.values():
            assert set(entry) == {"cam_K", "depth_scale", "cam_R_w2c", "cam_t_w2c"}
            np.testing.assert_allclose(np.reshape(entry["cam_K"], (3, 3)), K)
            assert entry["depth_scale"] == 1.0
            rot = np.reshape(entry["cam_R_w2c"], (3, 3))
            np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
            # A world point 1 m in front of the camera lands at 1000 mm on its axis.
            point_w = T_CAM_TO_WORLD[:, :3] @ [0.0, 0.0, 1.0] + T_CAM_TO_WORLD[:, 3]
            cam_mm = rot @ (point_w * 1000.0) + np.asarray(entry["cam_t_w2c"])
            np.testing.assert_allclose(cam_mm, [0.0, 0.0, 1000.0], atol=1e-9)

    def test_scene_gt_reproduces_the_object_poses(self, exported: Any) -> None:
        files, scenes = exported
        gt = _json(files, "scene_gt")
        for im_id, scene in scenes.items():
            entries = gt[str(im_id)]
            assert [e["obj_id"] for e in entries] == [NEAR, FAR, CUT]
            for entry in entries:
                assert set(entry) == {"obj_id", "cam_R_m2c", "cam_t_m2c"}
                assert len(entry["cam_R_m2c"]) == 9 and len(entry["cam_t_m2c"]) == 3
                m2c = make_pose(np.reshape(entry["cam_R_m2c"], (3, 3)),
                                np.asarray(entry["cam_t_m2c"]) / 1000.0)
                np.testing.assert_allclose(m2c, scene["cam"][entry["obj_id"]], atol=1e-12)
                np.testing.assert_allclose(compose_poses(T_CAM_TO_WORLD, m2c),
                                           scene["world"][entry["obj_id"]], atol=1e-12)

    def test_masks_are_the_full_and_the_visible_silhouettes(self, exported: Any) -> None:
        files, scenes = exported
        for im_id, scene in scenes.items():
            for gt_id, obj_id in enumerate((NEAR, FAR, CUT)):
                name = f"{im_id:06d}_{gt_id:06d}.png"
                full = _png(files[f"test/000007/mask/{name}"])
                visib = _png(files[f"test/000007/mask_visib/{name}"])
                assert full.dtype == np.uint8 and full.shape == (HEIGHT, WIDTH)
                assert set(np.unique(full)) <= {0, 255}
                np.testing.assert_array_equal(full > 0, scene["full"][obj_id])
                np.testing.assert_array_equal(visib > 0, scene["seg"] == obj_id)

    def test_gt_info_counts_and_boxes_agree_with_the_masks(self, exported: Any) -> None:
        files, scenes = exported
        info = _json(files, "scene_gt_info")
        for im_id, scene in scenes.items():
            for gt_id, obj_id in enumerate((NEAR, FAR, CUT)):
                entry = info[str(im_id)][gt_id]
                visible = scene["seg"] == obj_id
                full = scene["full"][obj_id]
                # The whole silhouette, the part beyond the image borders included.
                whole = _hull_mask(obj_id, scene["cam"][obj_id], -WIDTH, -HEIGHT, 3 * WIDTH,
                                   3 * HEIGHT)
                ys, xs = np.nonzero(whole)
                assert entry["bbox_obj"] == [xs.min() - WIDTH, ys.min() - HEIGHT,
                                             xs.max() - xs.min(), ys.max() - ys.min()]
                ys, xs = np.nonzero(visible)
                assert entry["bbox_visib"] == [xs.min(), ys.min(), xs.max() - xs.min(),
                                               ys.max() - ys.min()]
                assert entry["px_count_all"] == whole.sum()
                assert entry["px_count_visib"] == visible.sum()
                assert entry["px_count_valid"] == (full & (scene["depth"] > 0)).sum()
                assert entry["visib_fract"] == pytest.approx(visible.sum() / whole.sum())
                assert 0.0 < entry["visib_fract"] <= 1.0

    def test_occlusion_and_truncation_lower_the_visible_fraction(self, exported: Any) -> None:
        files, scenes = exported
        info = _json(files, "scene_gt_info")["0"]
        near, far, cut = info
        assert near["visib_fract"] < 1.0  # under the hand
        assert far["visib_fract"] < near["visib_fract"]  # behind the near box
        assert cut["px_count_all"] > scenes[0]["full"][CUT].sum()  # cut by the border
        assert cut["bbox_obj"][0] + cut["bbox_obj"][2] >= WIDTH

    def test_an_object_out_of_view_has_empty_boxes(self) -> None:
        files: dict[str, bytes] = {}
        writer = BopSceneWriter(files.__setitem__, 1, SceneCamera(K, np.eye(3, 4), WIDTH, HEIGHT),
                                MODELS)
        behind = make_pose(np.eye(3), np.array([0.0, 0.0, -1.0]))
        writer.add_image(0, np.zeros((HEIGHT, WIDTH), np.uint8), [(NEAR, behind)])
        writer.close()
        (entry,) = json.loads(files["test/000001/scene_gt_info.json"])["0"]
        assert entry == {"bbox_obj": [-1, -1, -1, -1], "bbox_visib": [-1, -1, -1, -1],
                         "px_count_all": 0, "px_count_valid": 0, "px_count_visib": 0,
                         "visib_fract": 0.0}

    def test_without_depth_every_silhouette_pixel_counts_as_valid(self) -> None:
        files: dict[str, bytes] = {}
        scene = _scene(0.0)
        writer = BopSceneWriter(files.__setitem__, 1,
                                SceneCamera(K, T_CAM_TO_WORLD, WIDTH, HEIGHT), MODELS)
        writer.add_image(0, scene["seg"], [(NEAR, scene["world"][NEAR])])
        writer.close()
        (entry,) = json.loads(files["test/000001/scene_gt_info.json"])["0"]
        assert entry["px_count_valid"] == scene["full"][NEAR].sum()
        assert not any("depth/" in name or "rgb/" in name for name in files)

    @pytest.mark.parametrize(("seg", "poses", "message"), [
        (np.zeros((HEIGHT, WIDTH + 1), np.uint8), [], r"seg must be \(120, 160\) uint8"),
        (np.zeros((HEIGHT, WIDTH), np.uint8), [(99, np.eye(3, 4))], r"object 99 has no model"),
        (np.zeros((HEIGHT, WIDTH), np.uint8), [(NEAR, np.eye(3, 4))] * 2, r"once per image"),
        (np.zeros((HEIGHT, WIDTH), np.uint8), [(NEAR, np.eye(4))],
         r"pose must have shape \(3, 4\), got \(4, 4\)"),
    ])
    def test_rejects_bad_input(self, seg: np.ndarray, poses: list[Any], message: str) -> None:
        writer = BopSceneWriter(lambda path, data: None, 1,
                                SceneCamera(K, np.eye(3, 4), WIDTH, HEIGHT), MODELS)
        with pytest.raises(ValueError, match=message):
            writer.add_image(0, seg, poses)


class TestFlaggedPoses:
    def test_a_flagged_pose_stays_in_scene_gt_with_a_note_and_leaves_the_targets(self) -> None:
        files: dict[str, bytes] = {}
        scene = _scene(0.0)
        writer = BopSceneWriter(files.__setitem__, 2, SceneCamera(K, T_CAM_TO_WORLD, WIDTH,
                                                                   HEIGHT), MODELS)
        notes = [{"pose_valid": True, "pose_flag": None},
                 {"pose_valid": False, "pose_flag": "depth sees through 80% of it"},
                 {"pose_valid": True, "pose_flag": None}]
        writer.add_image(5, scene["seg"], [(k, scene["world"][k]) for k in (NEAR, FAR, CUT)],
                         notes=notes)
        writer.close()
        gt = json.loads(files["test/000002/scene_gt.json"])["5"]
        info = json.loads(files["test/000002/scene_gt_info.json"])["5"]
        assert [g["obj_id"] for g in gt] == [NEAR, FAR, CUT]
        assert [i["dexlabel"] for i in info] == notes
        assert info[1]["visib_fract"] > 0.1  # visibility stays the truth
        # bop_toolkit's rule for targets: visib_fract >= 0.1, here also trusted.
        expected = [k for k, i in zip((NEAR, FAR, CUT), info, strict=True)
                    if i["visib_fract"] >= 0.1 and i["dexlabel"]["pose_valid"]]
        assert sorted(t["obj_id"] for t in writer.targets) == sorted(expected)
        assert FAR not in expected and NEAR in expected
        assert all((t["scene_id"], t["im_id"], t["inst_count"]) == (2, 5, 1)
                   for t in writer.targets)
        write_targets(files.__setitem__, writer.targets)
        assert json.loads(files["test_targets_bop19.json"]) == writer.targets

    def test_notes_must_match_the_posed_objects(self) -> None:
        scene = _scene(0.0)
        writer = BopSceneWriter(lambda p, d: None, 2, SceneCamera(K, T_CAM_TO_WORLD, WIDTH,
                                                                   HEIGHT), MODELS)
        with pytest.raises(ValueError, match="one entry per posed object"):
            writer.add_image(0, scene["seg"], [(NEAR, scene["world"][NEAR])], notes=[])


class TestModels:
    def test_models_info_gives_box_extents_and_diameter_in_mm(self, exported: Any) -> None:
        files, _ = exported
        infos = json.loads(files["models/models_info.json"])
        assert set(infos) == {str(k) for k in MODELS}
        for obj_id, half in HALF_SIZES.items():
            entry = infos[str(obj_id)]
            half_mm = np.asarray(half) * 1000.0
            np.testing.assert_allclose([entry["min_x"], entry["min_y"], entry["min_z"]],
                                       -half_mm)
            np.testing.assert_allclose([entry["size_x"], entry["size_y"], entry["size_z"]],
                                       2 * half_mm)
            assert entry["diameter"] == pytest.approx(2 * np.linalg.norm(half_mm))

    def test_models_info_lists_the_symmetries_of_each_box(self, exported: Any) -> None:
        files, _ = exported
        infos = json.loads(files["models/models_info.json"])
        # Boxes with three different sides: three half turns; the cube has more.
        assert len(infos[str(NEAR)]["symmetries_discrete"]) == 3
        assert len(infos[str(FAR)]["symmetries_discrete"]) == 3
        assert len(infos[str(CUT)]["symmetries_discrete"]) > 3
        assert all("symmetries_continuous" not in i for i in infos.values())

    def test_diameter_of_a_flat_model_is_searched_over_all_points(self) -> None:
        square = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0]], dtype=float)
        info = model_info(ObjectModel(1, square, np.array([[0, 1, 2], [1, 3, 2]])))
        assert info["diameter"] == pytest.approx(100 * np.sqrt(2))

    def test_ply_reads_back_in_mm(self, exported: Any, tmp_path: Path) -> None:
        files, _ = exported
        path = tmp_path / "obj.ply"
        path.write_bytes(files[f"models/obj_{NEAR:06d}.ply"])
        mesh = read_mesh(path)
        np.testing.assert_allclose(mesh.vertices, MODELS[NEAR].vertices * 1000.0, rtol=1e-6)
        np.testing.assert_array_equal(mesh.faces, MODELS[NEAR].faces)


class TestSyntheticCapture:
    def test_a_synthetic_capture_exports_its_poses_and_rendered_masks(
            self, small_capture: Path) -> None:
        """Pinhole views of a synthetic capture: the masks equal the renderer's seg where
        nothing occludes, and the exported poses equal the per-camera labels."""
        seq = next(small_capture.glob("*/*/meta.yml")).parent
        meta = yaml.safe_load((seq / "meta.yml").read_text())
        calibration = small_capture / "calibration"
        extrinsics = yaml.safe_load(next(calibration.glob("extrinsics_*/extrinsics.yml"))
                                    .read_text())["extrinsics"]
        models = {}
        for obj_id in meta["ycb_ids"]:
            mesh = read_mesh(small_capture / "models" / YCB_CLASSES[obj_id] / "textured_simple.obj")
            models[obj_id] = ObjectModel(obj_id, mesh.vertices, mesh.faces)
        checked = 0
        for scene_id, serial in enumerate(meta["serials"]):
            color = yaml.safe_load(next((calibration / "intrinsics").glob(f"{serial}_*.yml"))
                                   .read_text())["color"]
            if any(color["coeffs"]):
                continue  # BOP's masks are pinhole images; distorted views need undistorting
            K = np.array([[color["fx"], 0.0, color["ppx"]], [0.0, color["fy"], color["ppy"]],
                          [0.0, 0.0, 1.0]])
            T_c2w = np.reshape(extrinsics[serial], (3, 4))
            labels = [np.load(seq / serial / f"labels_{f:06d}.npz")
                      for f in range(meta["num_frames"])]
            height, width = labels[0]["seg"].shape
            files: dict[str, bytes] = {}
            writer = BopSceneWriter(files.__setitem__, scene_id,
                                    SceneCamera(K, T_c2w, width, height), models)
            for f, label in enumerate(labels):
                poses = [(obj_id, compose_poses(T_c2w, label["pose_y"][i].astype(np.float64)))
                         for i, obj_id in enumerate(meta["ycb_ids"])]
                writer.add_image(f, label["seg"], poses)
            writer.close()
            root = f"test/{scene_id:06d}"
            gt = json.loads(files[f"{root}/scene_gt.json"])
            for f, label in enumerate(labels):
                for i, entry in enumerate(gt[str(f)]):
                    m2c = make_pose(np.reshape(entry["cam_R_m2c"], (3, 3)),
                                    np.asarray(entry["cam_t_m2c"]) / 1000.0)
                    np.testing.assert_allclose(m2c, label["pose_y"][i], atol=1e-6)
                    name = f"{f:06d}_{i:06d}.png"
                    full = _png(files[f"{root}/mask/{name}"]) > 0
                    visib = _png(files[f"{root}/mask_visib/{name}"]) > 0
                    seen = label["seg"] == entry["obj_id"]
                    np.testing.assert_array_equal(visib, seen)
                    assert not (visib & ~full).any()
                    checked += int(seen.any())
        assert checked > 0
