"""The DexYCB toolkit's and bop_toolkit's own readers on our DexYCB and BOP exports.

Makes (or takes) a DexYCB export and a BOP export of one capture and reads them with the public
toolkits, unchanged, in a separate interpreter that has their dependencies:

- DexYCB (``dex_ycb_toolkit``): ``dex_ycb.DexYCBDataset`` builds the sample list (its subject
  names and camera serials are module constants, so they are set to the export's; it expects
  DexYCB's 100 sequences per subject, so the export is seen through a folder of links that
  repeats each subject's sequences up to 100, and every distinct camera-frame is then read
  once); every sample's label file is opened as the toolkit's evaluations read it (HPE: a
  ``joint_3d`` of all -1 is no hand; COCO: the hand's keypoints from ``joint_2d``, -1 meaning
  unlabelled; grasp: ``pose_y[ycb_grasp_ind]`` and ``pose_m`` all 0 meaning no hand), checked
  against the toolkit's documented label format (shapes, dtypes, seg values, the -1 / 0 rule
  holding for joint_3d, joint_2d and pose_m together); the calibration as ``SequenceLoader``
  reads it (intrinsics, extrinsics with ``apriltag`` and ``master``, ``mano_<calib>/mano.yml``
  betas); each object model through the toolkit's ``obj.OBJ`` with what its ``YCBLayer``
  asserts (one mesh, one group, normals indexed like vertices). Cross-camera consistency:
  every ``pose_y`` row is a rotation (orthonormal, det +1) and, taken to the world through each
  camera's extrinsics, agrees across the cameras and with ``pose.npz``; the labelled hand
  frames are the same in every camera and their ``joint_3d`` agree in the world. The MANO layer
  (``manopth``) needs the MANO model files, which are licensed and not shipped, so
  ``pose_m`` + betas are not turned into a mesh here.
- BOP (``bop_toolkit_lib``): ``dataset.bop_scenewise`` reads every scene and image (camera, gt,
  gt_info, rgb, depth, both masks) and ``inout`` the models (``load_ply``), ``models_info.json``
  and ``test_targets_bop19.json``; ``misc.get_symmetry_transformations`` expands each model's
  symmetries, each of which must map the model onto itself; ``misc.calc_pts_diameter`` and
  ``calc_3d_bbox`` recompute models_info; ``inout.get_im_targets`` with the BOP19 visibility
  bound of 0.1 gives the targets, which the export's list must equal less the flagged poses;
  visib_fract and px_count_visib agree with the masks; every pose is a rotation, and the
  scenes of one sequence (one per camera) agree on each object's world pose.

Prints one JSON object on its last line: {"ok", "dexycb": {...} or {"skipped"}, "bop": ...}.
Without the toolkits (``--dexycb-toolkit`` / ``DEXYCB_TOOLKIT``, ``--bop-toolkit`` /
``BOP_TOOLKIT``: the repositories' roots) it says so, skips, and exits 0. Their Python
dependencies (numpy, PyYAML; for BOP also pypng, imageio, scipy) are taken from
``--toolkit-python`` / ``TOOLKIT_PYTHON`` (default: this interpreter); a missing one is a skip
naming it.

    python bench/toolkit_readers.py --demo 12,3,1 --seed 7 --dexycb-toolkit ~/dex-ycb-toolkit \\
        --bop-toolkit ~/bop_toolkit --toolkit-python VENV/bin/python
    python bench/toolkit_readers.py --dexycb-export OUT.tar --bop-export OUT_BOP.tar ...

Length here: the reading takes seconds; ``--demo 12,3,1`` about one to two minutes on 2 quiet
cores (the README's demo path), 24,4,2 two to four.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from _demo_path import dexlabel, run_demo, unpacked

# Limits of the checks (float32 storage of poses and joints).
ORTHO_TOL = 1e-4          # max |R^T R - I| of a pose_y / cam_R_m2c rotation
AGREE_MM = 1.0            # cross-camera spread of a world position (mm)
AGREE_DEG = 0.05          # cross-camera spread of a world rotation (degrees)
PROJ_PX = 0.5             # joint_2d against K . joint_3d
SYMMETRY_REL = 0.01       # a symmetry's vertex displacement onto the model, share of diameter
BOP19_VISIB_MIN = 0.1     # BOP19's test-target visibility bound


# --- shared helpers (run in the toolkit's interpreter: numpy only) ----------------------------

def _rotation_problem(R: Any) -> float:
    import numpy as np

    R = np.asarray(R, np.float64)
    return float(max(np.abs(R.T @ R - np.eye(3)).max(), abs(np.linalg.det(R) - 1.0)))


def _angle_deg(Ra: Any, Rb: Any) -> float:
    import numpy as np

    # From the chord ||Ra - Rb||_F = 2 sqrt(2) sin(angle / 2): well conditioned near 0.
    chord = float(np.linalg.norm(np.asarray(Ra, np.float64) - np.asarray(Rb, np.float64)))
    return float(np.degrees(2.0 * np.arcsin(min(1.0, chord / (2.0 * np.sqrt(2.0))))))


def _quat_xyzw_to_matrix(q: Any) -> Any:
    import numpy as np

    x, y, z, w = (float(v) for v in np.asarray(q, np.float64) / np.linalg.norm(q))
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _surface_distance(points: Any, vertices: Any, faces: Any, candidates: int = 24) -> Any:
    """(P,) distance of each point to the mesh surface (its nearest of the ``candidates``
    triangles whose centroids lie nearest): the plane distance where the point projects inside
    a triangle, else the distance to the triangle's nearest edge."""
    import numpy as np
    from scipy.spatial import cKDTree

    tris = np.asarray(vertices, np.float64)[np.asarray(faces).astype(np.int64)]  # (T, 3, 3)
    k = min(candidates, len(tris))
    _, near = cKDTree(tris.mean(axis=1)).query(points, k=k)
    t = tris[np.asarray(near).reshape(len(points), k)]                   # (P, k, 3, 3)
    p = np.asarray(points, np.float64)[:, None, :]
    a, b, c = t[..., 0, :], t[..., 1, :], t[..., 2, :]
    n = np.cross(b - a, c - a)
    area2 = np.linalg.norm(n, axis=-1)
    unit = n / np.maximum(area2, 1e-12)[..., None]
    plane = np.einsum("pkd,pkd->pk", p - a, unit)
    q = p - plane[..., None] * unit
    inside = np.ones(plane.shape, bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("pkd,pkd->pk", np.cross(v - u, q - u), unit) >= 0
    best = np.where(inside & (area2 > 1e-12), np.abs(plane), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        edge = v - u
        s = np.clip(np.einsum("pkd,pkd->pk", p - u, edge)
                    / np.maximum(np.einsum("pkd,pkd->pk", edge, edge), 1e-12), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p - (u + s[..., None] * edge), axis=-1))
    return best.min(axis=1)


def _spread(poses: list[Any]) -> tuple[float, float]:
    """(largest translation difference mm, largest rotation difference deg) among 4x4 poses."""
    import numpy as np

    mm = deg = 0.0
    for a in poses[1:]:
        mm = max(mm, float(np.linalg.norm(a[:3, 3] - poses[0][:3, 3])) * 1000.0)
        deg = max(deg, _angle_deg(a[:3, :3], poses[0][:3, :3]))
    return mm, deg


# --- DexYCB --------------------------------------------------------------------------------

def _stage_dexycb(export: Path, stage: Path) -> tuple[list[str], list[str]]:
    """A folder of links over ``export`` in the shape DexYCBDataset expects: calibration and
    models as they are, each subject with 100 sequence entries (its own sequences, repeated).
    Returns (subject slots for _SUBJECTS, serial slots for _SERIALS)."""
    import yaml

    metas = sorted(export.glob("*/*/meta.yml"))
    if not metas:
        raise SystemExit(f"{export}: no <subject>/<sequence>/meta.yml")
    stage.mkdir(parents=True)
    for name in ("calibration", "models"):
        (stage / name).symlink_to((export / name).resolve())
    subjects: dict[str, list[Path]] = {}
    serials: list[str] = []
    for meta in metas:
        subjects.setdefault(meta.parent.parent.name, []).append(meta.parent)
        with meta.open() as f:
            for serial in yaml.safe_load(f)["serials"]:
                if serial not in serials:
                    serials.append(serial)
    for subject, sequences in subjects.items():
        (stage / subject).mkdir()
        for i in range(100):
            real = sequences[i % len(sequences)]
            name = real.name if i < len(sequences) else f"{real.name}~{i:02d}"
            (stage / subject / name).symlink_to(real.resolve())
    names = sorted(subjects)
    return [names[i % len(names)] for i in range(10)], [serials[i % len(serials)]
                                                       for i in range(8)]


def read_dexycb(export: Path, toolkit: Path, stage: Path) -> dict[str, Any]:
    """Run DexYCB's dataset loader over the export and check what its readers rely on."""
    import numpy as np
    import yaml

    sys.path.insert(0, str(toolkit))
    from dex_ycb_toolkit import dex_ycb  # the toolkit's own module, unchanged
    from dex_ycb_toolkit.obj import OBJ

    subject_slots, serial_slots = _stage_dexycb(export, stage)
    dex_ycb._SUBJECTS[:] = subject_slots   # configuration: the export's names
    dex_ycb._SERIALS[:] = serial_slots
    os.environ["DEX_YCB_DIR"] = str(stage)
    problems: list[str] = []

    def problem(text: str) -> None:
        if len(problems) < 30:
            problems.append(text)

    # Calibration as SequenceLoader reads it, per sequence; models as YCBLayer loads them.
    extrinsics: dict[str, dict[str, Any]] = {}
    world_pose_npz: dict[str, Any] = {}
    models_read = 0
    for meta_file in sorted(export.glob("*/*/meta.yml")):
        seq = meta_file.parent.resolve()
        with meta_file.open() as f:
            meta = yaml.load(f, Loader=yaml.FullLoader)
        with (stage / "calibration" / f"extrinsics_{meta['extrinsics']}"
              / "extrinsics.yml").open() as f:
            extr = yaml.load(f, Loader=yaml.FullLoader)
        T = {s: np.asarray(v, np.float64).reshape(3, 4) for s, v in extr["extrinsics"].items()}
        if "apriltag" not in T or extr["master"] not in meta["serials"]:
            problem(f"{seq.name}: extrinsics lacks apriltag or its master is not a serial")
        extrinsics[str(seq)] = {s: np.vstack([T[s], [0, 0, 0, 1]]) for s in meta["serials"]}
        for s in meta["serials"]:
            if _rotation_problem(T[s][:, :3]) > ORTHO_TOL:
                problem(f"{seq.name}/{s}: extrinsics rotation is not a rotation")
        for calib in meta["mano_calib"]:
            with (stage / "calibration" / f"mano_{calib}" / "mano.yml").open() as f:
                if len(yaml.load(f, Loader=yaml.FullLoader)["betas"]) != 10:
                    problem(f"mano_{calib}: betas are not 10 values")
        pose = np.load(meta_file.parent / "pose.npz")
        world_pose_npz[str(seq)] = (pose["pose_y"], pose["pose_m"])
        if pose["pose_y"].shape != (meta["num_frames"], len(meta["ycb_ids"]), 7):
            problem(f"{seq.name}: pose.npz pose_y has shape {pose['pose_y'].shape}")
        for ycb_id in meta["ycb_ids"]:
            obj = OBJ(str(stage / "models" / dex_ycb._YCB_CLASSES[ycb_id] / "textured_simple.obj"))
            group = obj.mesh_list[0].groups[0] if len(obj.mesh_list) == 1 else None
            if (group is None or len(obj.mesh_list[0].groups) != 1
                    or not (group.f_v == group.f_n).all() or len(obj.t[group.f_t]) == 0):
                problem(f"model {ycb_id}: not one mesh / one group with normals and texture "
                        "coordinates as YCBLayer asserts")
            models_read += 1

    dataset_reads: dict[str, int] = {}
    seen: set[tuple[str, str, int]] = set()
    labels_read = hpe_valid = coco_hands = grasp_hands = frames_present = 0
    rows = 0
    world: dict[tuple[str, int, int], list[Any]] = {}
    hands: dict[tuple[str, int], dict[str, Any]] = {}
    for name in ("s1_test",):
        dataset = dex_ycb.DexYCBDataset(*name.split("_"))
        dataset_reads[name] = len(dataset)
        for idx in range(len(dataset)):
            sample = dataset[idx]
            label_path = Path(sample["label_file"]).resolve()
            seq, serial = str(label_path.parent.parent), label_path.parent.name
            frame = int(label_path.stem.split("_")[1])
            if (seq, serial, frame) in seen:
                continue
            seen.add((seq, serial, frame))
            frames_present += Path(sample["color_file"]).exists() and Path(
                sample["depth_file"]).exists()
            label = np.load(sample["label_file"])
            labels_read += 1
            where = f"{Path(seq).name}/{serial}/{frame}"
            h, w = dataset.h, dataset.w
            ids = list(sample["ycb_ids"])
            K = np.array([[sample["intrinsics"]["fx"], 0, sample["intrinsics"]["ppx"]],
                          [0, sample["intrinsics"]["fy"], sample["intrinsics"]["ppy"]], [0, 0, 1]])
            shapes = {"seg": (h, w), "pose_y": (len(ids), 3, 4), "pose_m": (1, 51),
                      "joint_3d": (1, 21, 3), "joint_2d": (1, 21, 2)}
            for key, shape in shapes.items():
                dtype = np.uint8 if key == "seg" else np.float32
                if label[key].shape != shape or label[key].dtype != dtype:
                    problem(f"{where}: {key} {label[key].shape} {label[key].dtype}")
            if not set(np.unique(label["seg"]).tolist()) <= {0, 255, *ids}:
                problem(f"{where}: seg values outside 0, 255 and the ycb_ids")
            # HPE evaluation's rule: joint_3d all -1 is no hand; pose_m all 0 / joint_2d all -1
            # say the same (the toolkit's README).
            j3 = label["joint_3d"].reshape(21, 3)
            j2 = label["joint_2d"].reshape(21, 2)
            none_3d = bool(np.all(j3 == -1))
            none_2d = bool(np.all(j2 == -1))
            none_m = bool(np.all(label["pose_m"] == 0.0))
            if not none_3d == none_2d == none_m:
                problem(f"{where}: joint_3d none {none_3d}, joint_2d none {none_2d}, "
                        f"pose_m none {none_m}")
            if not none_3d:
                hpe_valid += 1
                if np.any(j3 == -1) or np.any(j3[:, 2] <= 0):
                    problem(f"{where}: a labelled joint_3d holds -1 or lies behind the camera")
                uvw = j3.astype(np.float64) @ K.T
                if np.abs(uvw[:, :2] / uvw[:, 2:] - j2).max() > PROJ_PX:
                    problem(f"{where}: joint_2d is not K . joint_3d")
                T = extrinsics[seq][serial]
                hands.setdefault((seq, frame), {})[serial] = j3 @ T[:3, :3].T + T[:3, 3]
            else:
                hands.setdefault((seq, frame), {})[serial] = None
            # COCO annotation's hand keypoints: (-1, -1) is unlabelled, else visible.
            if 255 in label["seg"] and not none_2d:
                coco_hands += 1
            # Grasp evaluation: the grasped object's pose row, and a hand unless pose_m is 0.
            grasp_row = label["pose_y"][sample["ycb_grasp_ind"]]
            grasp_hands += not none_m
            if grasp_row.shape != (3, 4):
                problem(f"{where}: pose_y[ycb_grasp_ind] has shape {grasp_row.shape}")
            for o, row in enumerate(label["pose_y"]):
                rows += 1
                if np.all(row == 0.0) or np.all(row == -1.0):
                    problem(f"{where}: pose_y row {o} is no pose")
                    continue
                if _rotation_problem(row[:, :3]) > ORTHO_TOL:
                    problem(f"{where}: pose_y row {o} is not a rotation")
                    continue
                T = extrinsics[seq][serial]
                world.setdefault((seq, frame, o), []).append(
                    T @ np.vstack([row.astype(np.float64), [0, 0, 0, 1]]))

    spread_mm = spread_deg = npz_mm = npz_deg = 0.0
    for (seq, frame, o), poses in world.items():
        mm, deg = _spread(poses)
        spread_mm, spread_deg = max(spread_mm, mm), max(spread_deg, deg)
        q = world_pose_npz[seq][0][frame, o]
        ref = np.eye(4)
        ref[:3, :3], ref[:3, 3] = _quat_xyzw_to_matrix(q[:4]), q[4:]
        mm, deg = _spread([ref, *poses])
        npz_mm, npz_deg = max(npz_mm, mm), max(npz_deg, deg)
    if spread_mm > AGREE_MM or spread_deg > AGREE_DEG:
        problem(f"pose_y rows disagree across cameras by {spread_mm:.3f} mm, {spread_deg:.4f} deg")
    if npz_mm > AGREE_MM or npz_deg > AGREE_DEG:
        problem(f"pose_y rows disagree with pose.npz by {npz_mm:.3f} mm, {npz_deg:.4f} deg")
    hand_mm = 0.0
    hand_frames = unlabelled_frames = 0
    for (seq, frame), per_camera in hands.items():
        labelled = [j for j in per_camera.values() if j is not None]
        if labelled and len(labelled) != len(per_camera):
            problem(f"{Path(seq).name} frame {frame}: hand labelled in some cameras only")
        if not labelled:
            unlabelled_frames += 1
            if np.any(world_pose_npz[seq][1][frame] != 0.0):
                problem(f"{Path(seq).name} frame {frame}: -1 joints but pose.npz pose_m set")
            continue
        hand_frames += 1
        hand_mm = max(hand_mm, max(float(np.linalg.norm(j - labelled[0], axis=1).max()) * 1000
                                   for j in labelled))
    if hand_mm > AGREE_MM:
        problem(f"joint_3d disagree across cameras by {hand_mm:.3f} mm")
    return {"ok": not problems, "dataset_samples": dataset_reads, "labels_read": labels_read,
            "frames_present": frames_present, "models_read": models_read,
            "hpe_valid_samples": hpe_valid, "coco_hand_annotations": coco_hands,
            "grasp_samples_with_hand": grasp_hands, "pose_y_rows": rows,
            "hand_frames_labelled": hand_frames, "hand_frames_unlabelled": unlabelled_frames,
            "cross_camera": {"pose_y_mm": round(spread_mm, 4), "pose_y_deg": round(spread_deg, 5),
                             "pose_npz_mm": round(npz_mm, 4), "pose_npz_deg": round(npz_deg, 5),
                             "joint_3d_mm": round(hand_mm, 4)},
            "mano_layer": "not run: manopth needs the licensed MANO model files",
            "problems": problems}


# --- BOP -------------------------------------------------------------------------------------

def read_bop(export: Path, toolkit: Path) -> dict[str, Any]:
    """Read the BOP export with bop_toolkit_lib and check what its evaluation relies on."""
    import numpy as np

    sys.path.insert(0, str(toolkit))
    from bop_toolkit_lib import inout, misc  # the toolkit's own modules, unchanged
    from bop_toolkit_lib.dataset import bop_scenewise

    problems: list[str] = []

    def problem(text: str) -> None:
        if len(problems) < 30:
            problems.append(text)

    infos = inout.load_json(export / "models" / "models_info.json", keys_to_int=True)
    symmetries = 0
    sym_worst = 0.0
    for obj_id, info in infos.items():
        model = inout.load_ply(str(export / "models" / f"obj_{obj_id:06d}.ply"))
        pts = model["pts"]
        diameter = misc.calc_pts_diameter(pts)
        if abs(diameter - info["diameter"]) > 1e-3 * diameter:
            problem(f"obj {obj_id}: diameter {info['diameter']} vs the model's {diameter:.3f}")
        box = misc.calc_3d_bbox(pts[:, 0], pts[:, 1], pts[:, 2])
        got = [info[k] for k in ("min_x", "min_y", "min_z", "size_x", "size_y", "size_z")]
        if np.abs(np.asarray(box) - np.asarray(got)).max() > 1e-3:
            problem(f"obj {obj_id}: min/size {got} vs the model's {box}")
        # Each symmetry must carry the model onto itself: every vertex, moved, lies on the
        # surface (a tessellated cylinder's rim lies within its sagitta of the side).
        worst = 0.0
        transforms = misc.get_symmetry_transformations(info, max_sym_disc_step=0.01)
        moved = np.concatenate([pts @ np.asarray(sym["R"]).T + np.asarray(sym["t"]).reshape(1, 3)
                                for sym in transforms])
        worst = float(_surface_distance(moved, pts, model["faces"]).max()) / diameter
        symmetries += len(transforms)
        sym_worst = max(sym_worst, worst)
        if worst > SYMMETRY_REL:
            problem(f"obj {obj_id}: a symmetry moves a vertex {worst:.3%} of the diameter "
                    "off the model")

    targets = inout.load_json(export / "test_targets_bop19.json")
    listed = {(t["scene_id"], t["im_id"], t["obj_id"]): t["inst_count"] for t in targets}
    expected: dict[tuple[int, int, int], int] = {}
    scenes_file = export / "scenes.json"
    scene_map = inout.load_json(scenes_file) if scenes_file.exists() else {}
    images = gts = flagged = 0
    world: dict[tuple[str, int, int], list[Any]] = {}
    scene_dirs = sorted(p for p in export.glob("*/[0-9][0-9][0-9][0-9][0-9][0-9]") if p.is_dir())
    for scene_dir in scene_dirs:
        scene_id = int(scene_dir.name)
        scene_info = bop_scenewise.read_scene_infos(scene_dir, read_image_ids=True)
        scene = bop_scenewise.load_scene_data(scene_dir)
        entry = scene_map.get(scene_dir.name, scene_map.get(str(scene_id), {}))
        sequence = (f"{entry.get('subject')}/{entry.get('sequence')}"
                    if isinstance(entry, dict) else str(entry))
        for im_id in scene_info["image_ids"]:
            data = bop_scenewise.load_image_data(
                scene_dir, im_id, load_rgb=scene_info["has_rgb"],
                load_depth=scene_info["has_depth"], load_mask_visib=True, load_mask=True,
                load_gt=True, load_gt_info=True)
            images += 1
            cam = scene["scene_camera"][im_id]
            T_w2c = np.eye(4)
            T_w2c[:3, :3], T_w2c[:3, 3] = cam["cam_R_w2c"], cam["cam_t_w2c"].ravel()
            for gt_id, (gt, gt_info) in enumerate(zip(data["gt"], data["gt_info"], strict=True)):
                gts += 1
                where = f"scene {scene_id} image {im_id} gt {gt_id}"
                if _rotation_problem(gt["cam_R_m2c"]) > ORTHO_TOL:
                    problem(f"{where}: cam_R_m2c is not a rotation")
                visib = int((data["mask_visib"][gt_id] > 0).sum())
                if visib != gt_info["px_count_visib"]:
                    problem(f"{where}: px_count_visib {gt_info['px_count_visib']} vs mask {visib}")
                if int((data["mask"][gt_id] > 0).sum()) > gt_info["px_count_all"]:
                    problem(f"{where}: mask larger than px_count_all")
                fract = visib / gt_info["px_count_all"] if gt_info["px_count_all"] else 0.0
                if abs(fract - gt_info["visib_fract"]) > 1e-3:
                    problem(f"{where}: visib_fract {gt_info['visib_fract']} vs {fract:.4f}")
                note = gt_info.get("dexlabel", {})
                flagged += note.get("pose_valid", True) is False
                T = np.eye(4)
                T[:3, :3], T[:3, 3] = gt["cam_R_m2c"], gt["cam_t_m2c"].ravel() / 1000.0
                c2w = np.linalg.inv(T_w2c)
                c2w[:3, 3] /= 1000.0
                world.setdefault((sequence, im_id, gt["obj_id"]), []).append(c2w @ T)
            trusted = [g for g, i in zip(data["gt"], data["gt_info"], strict=True)
                       if i.get("dexlabel", {}).get("pose_valid", True) is not False]
            trusted_info = [i for i in data["gt_info"]
                            if i.get("dexlabel", {}).get("pose_valid", True) is not False]
            for obj_id, target in inout.get_im_targets(trusted, trusted_info,
                                                       BOP19_VISIB_MIN).items():
                expected[(scene_id, im_id, obj_id)] = target["inst_count"]
    if listed != expected:
        extra = sorted(set(listed) - set(expected))[:5]
        missing = sorted(set(expected) - set(listed))[:5]
        problem(f"test_targets_bop19: {len(listed)} listed, {len(expected)} by the BOP19 rule "
                f"less flagged poses (extra {extra}, missing {missing})")
    spread_mm = spread_deg = 0.0
    for poses in world.values():
        mm, deg = _spread(poses)
        spread_mm, spread_deg = max(spread_mm, mm), max(spread_deg, deg)
    if scene_map and (spread_mm > AGREE_MM or spread_deg > AGREE_DEG):
        problem(f"a sequence's scenes disagree on a world pose by {spread_mm:.3f} mm, "
                f"{spread_deg:.4f} deg")
    return {"ok": not problems, "scenes": len(scene_dirs), "images_read": images,
            "ground_truths": gts, "flagged": flagged, "targets": len(listed),
            "models": len(infos), "symmetry_transforms": symmetries,
            "symmetry_worst_share": round(sym_worst, 6),
            "cross_scene": {"mm": round(spread_mm, 4), "deg": round(spread_deg, 5),
                            "sequences": len({k[0] for k in world}) if scene_map else None},
            "calc_gt_info": "not run: it renders with OpenGL, which this machine lacks",
            "problems": problems}


# --- orchestration (our interpreter) -----------------------------------------------------------

def _demo(spec: str, seed: int, fault: str | None, scratch: Path) -> tuple[Path, Path]:
    """(DexYCB export, BOP export) of the README's demo path in a new instance folder."""
    var = scratch / "var"
    run_demo(spec, seed, fault, var)
    out = scratch / "dexycb.tar", scratch / "bop.tar"
    dexlabel(var, "export", "--all", "--format", "dexycb", "--frames", "--out", str(out[0]))
    dexlabel(var, "export", "--all", "--format", "bop", "--frames", "--out", str(out[1]))
    return out


def _toolkit(option: str | None, env: str, marker: str) -> tuple[Path | None, str | None]:
    value = option or os.environ.get(env)
    if not value:
        return None, f"no toolkit given (--{env.lower().replace('_', '-')} or {env})"
    path = Path(value).expanduser()
    if not (path / marker).is_file():
        return None, f"{path} is not the toolkit's checkout (no {marker})"
    return path, None


def _run_reader(python: str, which: str, export: Path, toolkit: Path,
                scratch: Path) -> dict[str, Any]:
    done = subprocess.run([python, __file__, "--read", which, "--export-path", str(export),
                           "--toolkit-path", str(toolkit), "--scratch", str(scratch)],
                          capture_output=True, text=True)
    sys.stderr.write(done.stderr)
    lines = [ln for ln in done.stdout.splitlines() if ln.strip()]
    try:
        result: dict[str, Any] = json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError):
        tail = done.stderr.strip().splitlines()[-1:] or ["no output"]
        why = f"the reader failed (exit {done.returncode}): {tail[0]}"
        return {"ok": False, "problems": [why]}
    return result


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="Reading takes seconds; --demo 12,3,1 one to two minutes here.")
    parser.add_argument("--dexycb-toolkit", help="dex-ycb-toolkit checkout (or DEXYCB_TOOLKIT)")
    parser.add_argument("--bop-toolkit", help="bop_toolkit checkout (or BOP_TOOLKIT)")
    parser.add_argument("--toolkit-python", default=os.environ.get("TOOLKIT_PYTHON",
                                                                   sys.executable),
                        help="interpreter with the toolkits' dependencies (or TOOLKIT_PYTHON)")
    parser.add_argument("--dexycb-export", type=Path, help="a DexYCB export (folder/.zip/.tar)")
    parser.add_argument("--bop-export", type=Path, help="a BOP export (folder/.zip/.tar)")
    parser.add_argument("--demo", default="12,3,1",
                        help="FRAMES,VIEWS,OBJECTS of the demo made when no exports are given")
    parser.add_argument("--seed", type=int, default=7, help="--demo: the capture's seed")
    parser.add_argument("--fault", help="--demo: a rig fault for dexlabel synth --fault "
                                        "(e.g. late:1, which leaves hand frames flagged)")
    parser.add_argument("--keep", type=Path, help="a new folder to keep the demo and exports in")
    parser.add_argument("--read", choices=("dexycb", "bop"), help=argparse.SUPPRESS)
    parser.add_argument("--export-path", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--toolkit-path", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--scratch", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()

    if args.read:   # inside the toolkit's interpreter
        try:
            if args.read == "dexycb":
                result = read_dexycb(args.export_path, args.toolkit_path, args.scratch / "stage")
            else:
                result = read_bop(args.export_path, args.toolkit_path)
        except ModuleNotFoundError as error:
            result = {"skipped": f"the toolkit needs the module {error.name!r}, which "
                                 f"{sys.executable} lacks (give --toolkit-python)"}
        print(json.dumps(result))
        return

    dexycb_tk, dexycb_why = _toolkit(args.dexycb_toolkit, "DEXYCB_TOOLKIT",
                                     "dex_ycb_toolkit/dex_ycb.py")
    bop_tk, bop_why = _toolkit(args.bop_toolkit, "BOP_TOOLKIT", "bop_toolkit_lib/inout.py")
    summary: dict[str, Any] = {"demo": None, "seed": None, "fault": None}
    if dexycb_tk is None and bop_tk is None:
        print(f"SKIP: the toolkits are not present ({dexycb_why}; {bop_why})", file=sys.stderr)
        summary.update(dexycb={"skipped": dexycb_why}, bop={"skipped": bop_why}, ok=True)
        print(json.dumps(summary))
        return
    with tempfile.TemporaryDirectory(prefix="dexlabel-toolkit-readers-") as tmp:
        scratch = Path(tmp) if args.keep is None else args.keep
        scratch.mkdir(parents=True, exist_ok=args.keep is None)
        exports = (args.dexycb_export, args.bop_export)
        if (dexycb_tk and exports[0] is None) or (bop_tk and exports[1] is None):
            made = _demo(args.demo, args.seed, args.fault, scratch / "demo")
            summary.update(demo=args.demo, seed=args.seed, fault=args.fault)
            exports = (exports[0] or made[0], exports[1] or made[1])
        for name, toolkit, why, export in (("dexycb", dexycb_tk, dexycb_why, exports[0]),
                                           ("bop", bop_tk, bop_why, exports[1])):
            if toolkit is None or export is None:
                summary[name] = {"skipped": why}
                continue
            folder = unpacked(export, scratch / f"{name}-export")
            summary[name] = _run_reader(args.toolkit_python, name, folder, toolkit,
                                        scratch / f"{name}-read")
    summary["ok"] = all(part.get("ok", "skipped" in part)
                        for part in (summary["dexycb"], summary["bop"]))
    print(json.dumps(summary))
    sys.exit(0 if summary["ok"] else 1)


if __name__ == "__main__":
    main()
