"""Checks of exported archives with each format's own reader (pycocotools for COCO, the BOP
format's documented structure, our CVAT reader, the JSON document), against what is stored: the
accepted assignments' keyframes and the current solve's arrays."""

from __future__ import annotations

import json
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval
from sqlalchemy import select

from backend.annotation.models import Assignment, Task
from backend.captures.assets import load_mesh
from backend.captures.models import Camera, SceneObject
from backend.db import session_scope
from backend.solve.results import decode_result
from backend.solve.service import current_run
from backend.storage import get_storage
from worker.formats.coco import HAND_CATEGORY_ID
from worker.formats.cvat_read import read_cvat_video
from worker.geometry.transforms import invert_pose
from worker.tracks.interpolate import dense_track
from worker.tracks.keyframes import as_keyframes
from worker.tracks.spans import frame_spans


@dataclass
class StoredWork:
    """One accepted assignment as stored: its view's serial, target and raw keyframes."""

    assignment_id: int
    serial: str
    target_key: str
    keyframes: list[list[list[Any]]]


def accepted_work(sequence_id: int) -> list[StoredWork]:
    with session_scope() as s:
        rows = s.execute(select(Assignment, Task.target_key, Camera.serial)
                         .join(Task, Assignment.task_id == Task.id)
                         .join(Camera, Task.camera_id == Camera.id)
                         .where(Task.sequence_id == sequence_id,
                                Assignment.status == "approved")
                         .order_by(Assignment.id)).all()
        out = []
        for assignment, target_key, serial in rows:
            points: list[list[list[Any]]] = [[] for _ in assignment.tracks]
            for track in assignment.tracks:
                points[track.point_index] = [list(k) for k in track.keyframes]
            out.append(StoredWork(assignment.id, serial, target_key, points))
        return out


def stored_solve(sequence_id: int) -> dict[str, np.ndarray]:
    with session_scope() as s:
        run = current_run(s, sequence_id)
        assert run is not None and run.result_key
        key = run.result_key
    return decode_result(get_storage().get_bytes(key))


def cameras(sequence_id: int) -> dict[str, dict[str, Any]]:
    with session_scope() as s:
        cams = s.scalars(select(Camera).where(Camera.sequence_id == sequence_id)).all()
        return {c.serial: {"K": np.array([[c.fx, 0, c.ppx], [0, c.fy, c.ppy], [0, 0, 1.0]]),
                           "size": (c.width, c.height), "T": np.asarray(c.extrinsics)}
                for c in cams}


# COCO


def check_coco(archive: zipfile.ZipFile, tmp: Path, sequence_id: int) -> None:
    """pycocotools loads the export; COCOeval against itself with the stated sigmas gives AP 1;
    every hand keypoint follows the v / num_keypoints rules for the accepted labels."""
    path = tmp / "annotations.json"
    path.write_bytes(archive.read("annotations.json"))
    gt = COCO(str(path))
    sigmas = np.asarray(gt.dataset["info"]["oks_sigmas"])
    assert sigmas.shape == (21,)
    assert gt.loadCats([HAND_CATEGORY_ID])[0]["sigmas"] == sigmas.tolist()
    hands = [dict(a, score=1.0) for a in gt.loadAnns(gt.getAnnIds(catIds=[HAND_CATEGORY_ID]))
             if a["num_keypoints"] > 0]
    assert hands
    evaluation = COCOeval(gt, gt.loadRes(hands), iouType="keypoints")
    evaluation.params.kpt_oks_sigmas = sigmas
    evaluation.params.catIds = [HAND_CATEGORY_ID]
    evaluation.evaluate()
    evaluation.accumulate()
    evaluation.summarize()
    assert evaluation.stats[0] == 1.0

    stored = {w.serial: w for w in accepted_work(sequence_id) if w.target_key.startswith("hand")}
    counts = {0: 0, 1: 0, 2: 0}
    for image in gt.dataset["images"]:
        assert image["sequence_id"] == sequence_id
        width, height = image["width"], image["height"]
        anns = gt.loadAnns(gt.getAnnIds(imgIds=[image["id"]], catIds=[HAND_CATEGORY_ID]))
        expected = []
        for point in stored[image["serial"]].keyframes:
            [(_, x, y, visible, *_source)] = [k for k in point if k[0] == image["frame"]]
            inside = x is not None and -0.5 <= x < width - 0.5 and -0.5 <= y < height - 0.5
            expected.append((x, y, (2 if visible else 1) if inside else 0))
        if not any(v for *_, v in expected):
            assert all(a["num_keypoints"] == 0 for a in anns)
            continue
        [ann] = anns
        keypoints = np.asarray(ann["keypoints"], dtype=np.float64).reshape(21, 3)
        assert ann["num_keypoints"] == sum(v > 0 for *_, v in expected)
        assert ann["iscrowd"] == 0 and len(ann["bbox"]) == 4 and ann["area"] > 0
        for (x, y, v), (kx, ky, kv) in zip(expected, keypoints, strict=True):
            counts[v] += 1
            assert kv == v
            if v:
                assert abs(kx - x) <= 5e-4 and abs(ky - y) <= 5e-4
            else:
                assert kx == 0 and ky == 0
    assert counts[1] > 0 and counts[2] > 0, f"visible and occluded joints expected: {counts}"


# BOP

_BOP_FILE = re.compile(
    r"^(models/(models_info\.json|obj_\d{6}\.ply)|scenes\.json|test_targets_bop19\.json|"
    r"test/\d{6}/(scene_camera\.json|scene_gt\.json|scene_gt_info\.json|"
    r"(mask|mask_visib)/\d{6}_\d{6}\.png|rgb/\d{6}\.jpg|depth/\d{6}\.png))$")
_INFO_KEYS = {"bbox_obj", "bbox_visib", "px_count_all", "px_count_valid", "px_count_visib",
              "visib_fract"}


def _png(data: bytes) -> np.ndarray:
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert image is not None
    return image


def _ply_vertices(data: bytes) -> np.ndarray:
    head, _, body = data.partition(b"end_header\n")
    count = int(re.search(rb"element vertex (\d+)", head).group(1))  # type: ignore[union-attr]
    return np.frombuffer(body[:count * 12], dtype="<f4").reshape(count, 3)


def check_bop(archive: zipfile.ZipFile, sequence_id: int) -> None:
    """Every file of the archive: names, keys, shapes, millimetres, and object poses that give
    back the stored solve's through the world-to-camera pose."""
    names = archive.namelist()
    bad = [n for n in names if not _BOP_FILE.match(n)]
    assert not bad, bad
    arrays = stored_solve(sequence_id)
    cams = cameras(sequence_id)
    with session_scope() as s:
        objects = {o.ycb_id: (o.index, load_mesh(get_storage(), o.mesh_key).vertices)
                   for o in s.scalars(select(SceneObject)
                                      .where(SceneObject.sequence_id == sequence_id))}
    infos = json.loads(archive.read("models/models_info.json"))
    assert set(infos) == {str(i) for i in objects}
    for obj_id, (_, vertices) in objects.items():
        info, mm = infos[str(obj_id)], vertices * 1000.0
        np.testing.assert_allclose([info[f"min_{a}"] for a in "xyz"], mm.min(axis=0), atol=1e-6)
        np.testing.assert_allclose([info[f"size_{a}"] for a in "xyz"], np.ptp(mm, axis=0),
                                   atol=1e-6)
        assert np.ptp(mm, axis=0).max() <= info["diameter"] <= np.linalg.norm(np.ptp(mm, axis=0))
        ply = _ply_vertices(archive.read(f"models/obj_{obj_id:06d}.ply"))
        np.testing.assert_allclose(ply, mm, atol=1e-3)
    scenes = json.loads(archive.read("scenes.json"))
    assert sorted(scenes) == [f"{i:06d}" for i in range(1, len(cams) + 1)]
    for scene_id, scene in scenes.items():
        assert scene["sequence_id"] == sequence_id
        _check_bop_scene(archive, f"test/{scene_id}", cams[scene["serial"]], arrays, objects)


def _check_bop_scene(archive: zipfile.ZipFile, root: str, cam: dict[str, Any],
                     arrays: dict[str, np.ndarray], objects: dict[int, Any]) -> None:
    width, height = cam["size"]
    w2c = invert_pose(cam["T"])
    camera = json.loads(archive.read(f"{root}/scene_camera.json"))
    gt = json.loads(archive.read(f"{root}/scene_gt.json"))
    gt_info = json.loads(archive.read(f"{root}/scene_gt_info.json"))
    frames = arrays["object_poses"].shape[1]
    assert list(camera) == list(gt) == list(gt_info) == [str(f) for f in range(frames)]
    for im, entry in camera.items():
        assert set(entry) == {"cam_K", "depth_scale", "cam_R_w2c", "cam_t_w2c"}
        assert entry["cam_K"] == cam["K"].ravel().tolist() and entry["depth_scale"] == 1.0
        np.testing.assert_allclose(entry["cam_R_w2c"], w2c[:, :3].ravel(), atol=1e-12)
        np.testing.assert_allclose(entry["cam_t_w2c"], w2c[:, 3] * 1000.0, atol=1e-9)
        R_w2c = np.asarray(entry["cam_R_w2c"]).reshape(3, 3)
        t_w2c = np.asarray(entry["cam_t_w2c"])
        f = int(im)
        seen = [(index, ycb) for ycb, (index, _) in objects.items()
                if np.isfinite(arrays["object_poses"][index, f]).all()]
        assert sorted(g["obj_id"] for g in gt[im]) == sorted(ycb for _, ycb in seen)
        assert len(gt_info[im]) == len(gt[im])
        for g_id, (g, info) in enumerate(zip(gt[im], gt_info[im], strict=True)):
            assert set(g) == {"obj_id", "cam_R_m2c", "cam_t_m2c"}
            assert set(info) == _INFO_KEYS | {"dexlabel"}
            assert set(info["dexlabel"]) == {"pose_valid", "pose_confidence", "pose_flag",
                                             "provenance"}
            R = np.asarray(g["cam_R_m2c"]).reshape(3, 3)
            t_mm = np.asarray(g["cam_t_m2c"])
            assert 100 < t_mm[2] < 5000, f"cam_t_m2c must be millimetres, got {t_mm}"
            world = np.concatenate([R_w2c.T @ R, (R_w2c.T @ (t_mm - t_w2c) / 1000.0)[:, None]],
                                   axis=1)
            np.testing.assert_allclose(world, arrays["object_poses"][objects[g["obj_id"]][0], f],
                                       atol=1e-9)
            name = f"{int(im):06d}_{g_id:06d}.png"
            full, visib = (_png(archive.read(f"{root}/{kind}/{name}"))
                           for kind in ("mask", "mask_visib"))
            for mask in (full, visib):
                assert mask.shape == (height, width) and set(np.unique(mask)) <= {0, 255}
            assert info["px_count_visib"] == int((visib > 0).sum())
            assert info["px_count_all"] >= int((full > 0).sum()) >= info["px_count_visib"]
            assert 0.0 <= info["visib_fract"] <= 1.0
            assert len(info["bbox_obj"]) == len(info["bbox_visib"]) == 4
        rgb = _png(archive.read(f"{root}/rgb/{f:06d}.jpg"))
        depth = _png(archive.read(f"{root}/depth/{f:06d}.png"))
        assert rgb.shape == (height, width, 3)
        assert depth.shape == (height, width) and depth.dtype == np.uint16


# CVAT


def check_cvat(archive: zipfile.ZipFile, sequence_id: int) -> None:
    """Each view's XML read back gives the stored keyframes and occlusion spans of every
    accepted assignment of that view."""
    stored = accepted_work(sequence_id)
    xmls = [n for n in archive.namelist() if n.endswith(".xml")]
    assert len(xmls) == len({w.serial for w in stored})
    for name in xmls:
        serial = Path(name).stem
        with archive.open(name) as fh:
            video = read_cvat_video(fh)
        work = [w for w in stored if w.serial == serial]
        assert len(video.tracks) == len(work)
        for track, w in zip(video.tracks, work, strict=True):
            kind, index = w.target_key.split(":")
            assert track.label == "hand" if kind == "hand" else track.label.startswith(
                f"object {index} ")
            for p, (read, given) in enumerate(zip(track.keyframes, w.keyframes, strict=True)):
                expected = as_keyframes(given)
                assert [(k.frame, k.visible, k.has_position) for k in read] == [
                    (k.frame, k.visible, k.has_position) for k in expected], (serial, p)
                for k, e in zip(read, expected, strict=True):
                    if e.has_position:  # CVAT writes 2 decimals
                        assert abs(k.x - e.x) <= 0.005 + 1e-9  # type: ignore[operator]
                        assert abs(k.y - e.y) <= 0.005 + 1e-9  # type: ignore[operator]
                dense = dense_track(given, video.num_frames)
                spans = frame_spans((dense.state != 0) & ~dense.visible)
                assert track.occluded[p] == tuple((a, b) for a, b in spans), (serial, p)
