"""The DexYCB raw layout: the one place that knows its file names, YAML keys, npz keys and
"no label" values. The importer reads with it, the synthetic writer and the export write with it.

Layout (paths relative to a capture root; ``WxH`` is the image size)::

    calibration/intrinsics/<serial>_<W>x<H>.yml     color: {fx, fy, ppx, ppy[, width, height,
                                                    coeffs]} (and depth: the same, aligned)
    calibration/extrinsics_<name>/extrinsics.yml    extrinsics: {<serial>: 12 floats,
                                                    apriltag: 12 floats}, master
    calibration/mano_<calib>/mano.yml               betas: 10 floats
    models/<ycb name>/textured_simple.obj           (+ .obj.mtl, texture_map.png)
    <subject>/<sequence>/meta.yml                   serials, num_frames, ycb_ids, ycb_grasp_ind,
                                                    mano_sides, mano_calib, extrinsics
    <subject>/<sequence>/pose.npz                   pose_y (F, O, 7) qx qy qz qw tx ty tz,
                                                    pose_m (F, H, 51); world frame
    <subject>/<sequence>/<serial>/color_%06d.jpg, aligned_depth_to_color_%06d.png (uint16 mm),
                                  labels_%06d.npz
    <subject>/<sequence>/<serial>.mp4|.avi|.mov|.mkv  (instead of the folder: colour only)

Per camera and frame ``labels_%06d.npz``: ``seg`` uint8 (H, W) (0 background, the object's
YCB id, 255 the hand), ``pose_y`` float32 (O, 3, 4) object-to-camera, ``pose_m`` float32 (1, 51)
in the camera frame, ``joint_3d`` float32 (1, 21, 3) metres in the camera frame, ``joint_2d``
float32 (1, 21, 2) pixels. Where the hand has no label (or its label is flagged), ``joint_3d``
and ``joint_2d`` are all -1 and ``pose_m`` all 0, as the DexYCB toolkit documents and reads
them; a ``pose_y`` row is -1 only where no pose exists at all. In ``pose.npz`` a frame without
a hand pose has ``pose_m`` all 0 and one without an object pose the row [0, 0, 0, 1, 0, 0, 0],
which the toolkit's viewer reads as absent. The export adds its own keys beside these (see
:mod:`worker.formats.dexycb_flags`); readers that look keys up by name are unaffected.

Extrinsics are camera-to-world (the master frame), 3x4 row-major, metres; ``apriltag`` is the
table's frame in the world (DexYCB's viewer crops its point clouds in it; its loader needs the
entry). DexYCB's own loader
builds K from fx, fy, ppx, ppy alone and ignores distortion: a capture written for it has
pinhole images, which :mod:`worker.formats.dexycb_frames` makes (images undistorted, labels
projected with the same K), and meta.yml says so (``META_UNDISTORTED``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from worker.geometry.transforms import matrix_to_quaternion

# DexYCB's object class table: meta.yml's ``ycb_ids`` index into it, and the ids double as the
# object values in the per-frame segmentation masks (0 is background, HAND_SEG_VALUE the hand).
YCB_CLASSES: dict[int, str] = {
    1: "002_master_chef_can",
    2: "003_cracker_box",
    3: "004_sugar_box",
    4: "005_tomato_soup_can",
    5: "006_mustard_bottle",
    6: "007_tuna_fish_can",
    7: "008_pudding_box",
    8: "009_gelatin_box",
    9: "010_potted_meat_can",
    10: "011_banana",
    11: "019_pitcher_base",
    12: "021_bleach_cleanser",
    13: "024_bowl",
    14: "025_mug",
    15: "035_power_drill",
    16: "036_wood_block",
    17: "037_scissors",
    18: "040_large_marker",
    19: "051_large_clamp",
    20: "052_extra_large_clamp",
    21: "061_foam_brick",
}

BACKGROUND_SEG_VALUE = 0
HAND_SEG_VALUE = 255
IMAGE_WIDTH = 640
IMAGE_HEIGHT = 480
FPS = 30.0
# Every entry of joint_3d / joint_2d (and of a pose_y row) without a label.
NO_LABEL = -1.0
# Every entry of pose_m without a label (the toolkit tests pose_m == 0).
NO_POSE_M = 0.0
# pose.npz's pose_y row of an object without a pose (the toolkit's viewer skips it).
NO_POSE_ROW = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)

# --- file and folder names -----------------------------------------------------------------

CALIBRATION_DIR = "calibration"
INTRINSICS_DIR = f"{CALIBRATION_DIR}/intrinsics"
MODELS_DIR = "models"
MODEL_OBJ = "textured_simple.obj"
MODEL_MTL = "textured_simple.obj.mtl"
MODEL_TEXTURE = "texture_map.png"
MODEL_SUFFIXES = (".obj", ".ply")
META_FILE = "meta.yml"
POSE_FILE = "pose.npz"
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv")
COLOR_GLOB = "color_*.jpg"
META_GLOB = f"*/*/{META_FILE}"


def intrinsics_file(serial: str, width: int, height: int) -> str:
    return f"{INTRINSICS_DIR}/{serial}_{width}x{height}.yml"


def intrinsics_glob(serial: str) -> str:
    """The glob (inside INTRINSICS_DIR) of a camera's intrinsics at any image size."""
    return f"{serial}_*.yml"


def intrinsics_size(stem: str) -> tuple[int, int] | None:
    """(width, height) from an intrinsics file's stem ``<serial>_<W>x<H>``; None if absent."""
    try:
        width, height = (int(v) for v in stem.rsplit("_", 1)[-1].split("x"))
    except ValueError:
        return None
    return width, height


def extrinsics_file(name: str) -> str:
    return f"{CALIBRATION_DIR}/extrinsics_{name}/extrinsics.yml"


def mano_file(calib: str) -> str:
    return f"{CALIBRATION_DIR}/mano_{calib}/mano.yml"


def model_dir(object_name: str) -> str:
    return f"{MODELS_DIR}/{object_name}"


def sequence_dir(subject: str, sequence: str) -> str:
    return f"{subject}/{sequence}"


def color_file(index: int) -> str:
    return f"color_{index:06d}.jpg"


def depth_file(index: int) -> str:
    return f"aligned_depth_to_color_{index:06d}.png"


def labels_file(index: int) -> str:
    return f"labels_{index:06d}.npz"


# --- YAML and npz keys ---------------------------------------------------------------------

COLOR = "color"
DEPTH = "depth"
INTRINSIC_KEYS = ("fx", "fy", "ppx", "ppy")
EXTRINSICS = "extrinsics"
MASTER = "master"
APRILTAG = "apriltag"
BETAS = "betas"
META_SERIALS = "serials"
META_NUM_FRAMES = "num_frames"
META_YCB_IDS = "ycb_ids"
META_GRASP_IND = "ycb_grasp_ind"
META_MANO_SIDES = "mano_sides"
META_MANO_CALIB = "mano_calib"
META_EXTRINSICS = "extrinsics"
# Written by the export: the serials whose frames and labels were undistorted to the pinhole
# model of their intrinsics (their coeffs are written as zeros), and the coefficients removed.
META_UNDISTORTED = "undistorted"
POSE_Y = "pose_y"
POSE_M = "pose_m"
SEG = "seg"
JOINT_3D = "joint_3d"
JOINT_2D = "joint_2d"
LABEL_KEYS = (SEG, POSE_Y, POSE_M, JOINT_3D, JOINT_2D)
NUM_JOINTS = 21
POSE_M_SIZE = 51

# DexYCB's evaluation setups: s0 splits by sequence, s1 holds out subjects, s2 camera views,
# s3 grasped objects (the benchmark's own proportions of its 10 subjects, 8 views, 20 objects).
SPLIT_SETUPS = ("s0", "s1", "s2", "s3")
SPLIT_NAMES = ("train", "val", "test")


# --- documents -----------------------------------------------------------------------------

def intrinsics_doc(fx: float, fy: float, ppx: float, ppy: float, width: int, height: int,
                   coeffs: Sequence[float] | np.ndarray) -> dict[str, Any]:
    """An intrinsics file: the colour camera's, and the depth's (aligned to colour: the same)."""
    entry = {"fx": float(fx), "fy": float(fy), "ppx": float(ppx), "ppy": float(ppy),
             "width": int(width), "height": int(height), "coeffs": [float(c) for c in coeffs]}
    return {COLOR: entry, DEPTH: dict(entry)}


def extrinsics_doc(table: Mapping[str, np.ndarray], master: str,
                   tag: np.ndarray | None = None) -> dict[str, Any]:
    """extrinsics.yml: camera-to-world (3, 4) per serial as 12 row-major floats, metres, and
    the table's frame in the world as ``apriltag`` (``tag``; the world origin when unknown)."""
    poses = {serial: [float(x) for x in np.asarray(T).reshape(-1)]
             for serial, T in table.items()}
    frame = np.eye(4)[:3] if tag is None else np.asarray(tag, dtype=np.float64)
    poses[APRILTAG] = [float(x) for x in frame.reshape(-1)]
    return {EXTRINSICS: poses, MASTER: master}


def mano_doc(betas: Sequence[float] | np.ndarray) -> dict[str, Any]:
    return {BETAS: [float(b) for b in betas]}


def meta_doc(serials: Sequence[str], num_frames: int, ycb_ids: Sequence[int], grasp_ind: int,
             mano_sides: Sequence[str], mano_calib: Sequence[str], extrinsics: str,
             undistorted: Mapping[str, Sequence[float]] | None = None) -> dict[str, Any]:
    """meta.yml of a sequence; ``undistorted`` (serial -> removed coeffs) only when given."""
    doc: dict[str, Any] = {
        META_SERIALS: list(serials), META_NUM_FRAMES: int(num_frames),
        META_YCB_IDS: [int(i) for i in ycb_ids], META_GRASP_IND: int(grasp_ind),
        META_MANO_SIDES: list(mano_sides), META_MANO_CALIB: list(mano_calib),
        META_EXTRINSICS: extrinsics,
    }
    if undistorted:
        doc[META_UNDISTORTED] = {s: [float(c) for c in v] for s, v in undistorted.items()}
    return doc


def pose_arrays(object_poses: np.ndarray, pose_m: np.ndarray) -> dict[str, np.ndarray]:
    """pose.npz's arrays from world-frame poses, float32.

    object_poses: (F, O, 3, 4) object-to-world, metres (NaN: no label). pose_m: (F, H, 51).
    Returns pose_y (F, O, 7) as quaternion xyzw + translation (NO_POSE_ROW where the pose is
    not finite), and pose_m (F, H, 51) (NO_POSE_M where it is not finite).
    """
    object_poses = np.asarray(object_poses, dtype=np.float64)
    pose_m = np.asarray(pose_m, dtype=np.float64)
    if object_poses.ndim != 4 or object_poses.shape[2:] != (3, 4):
        raise ValueError(f"object_poses must have shape (F, O, 3, 4), got {object_poses.shape}")
    if pose_m.ndim != 3 or pose_m.shape[2] != POSE_M_SIZE:
        raise ValueError(f"pose_m must have shape (F, H, 51), got {pose_m.shape}")
    finite = np.isfinite(object_poses).all(axis=(2, 3))
    safe = np.where(finite[..., None, None], object_poses, np.eye(3, 4))
    quat = matrix_to_quaternion(safe[..., :3])
    pose_y = np.concatenate([quat, safe[..., 3]], axis=-1)
    pose_y[~finite] = NO_POSE_ROW
    out_m = np.where(np.isfinite(pose_m).all(axis=-1, keepdims=True), pose_m, NO_POSE_M)
    return {POSE_Y: pose_y.astype(np.float32), POSE_M: out_m.astype(np.float32)}


def label_arrays(seg: np.ndarray, pose_y: np.ndarray, pose_m: np.ndarray | None,
                 joint_3d: np.ndarray | None, joint_2d: np.ndarray | None) -> dict[str, np.ndarray]:
    """One camera frame's labels, DexYCB's dtypes and shapes; NO_LABEL for what is missing.

    seg: (H, W) uint8. pose_y: (O, 3, 4) object-to-camera (a non-finite pose is unlabelled).
    pose_m: (51,) camera frame; joint_3d: (21, 3) metres, camera frame; joint_2d: (21, 2) px.
    None (or any non-finite entry) leaves the hand unlabelled: joint_3d and joint_2d NO_LABEL,
    pose_m NO_POSE_M.
    """
    seg = np.asarray(seg)
    if seg.ndim != 2:
        raise ValueError(f"seg must have shape (H, W), got {seg.shape}")
    pose_y = np.asarray(pose_y, dtype=np.float64)
    if pose_y.ndim != 3 or pose_y.shape[1:] != (3, 4):
        raise ValueError(f"pose_y must have shape (O, 3, 4), got {pose_y.shape}")
    pose_y = np.where(np.isfinite(pose_y).all(axis=(1, 2), keepdims=True), pose_y, NO_LABEL)
    hand = (pose_m, joint_3d, joint_2d)
    shapes = ((POSE_M_SIZE,), (NUM_JOINTS, 3), (NUM_JOINTS, 2))
    arrays = []
    labelled = all(a is not None and np.isfinite(np.asarray(a, float)).all() for a in hand)
    for value, shape, empty in zip(hand, shapes, (NO_POSE_M, NO_LABEL, NO_LABEL), strict=True):
        if value is not None and np.asarray(value).shape != shape:
            raise ValueError(f"hand label must have shape {shape}, got {np.asarray(value).shape}")
        arrays.append(np.asarray(value, np.float64) if labelled else np.full(shape, empty))
    return {SEG: seg.astype(np.uint8), POSE_Y: pose_y.astype(np.float32),
            POSE_M: arrays[0][None].astype(np.float32),
            JOINT_3D: arrays[1][None].astype(np.float32),
            JOINT_2D: arrays[2][None].astype(np.float32)}


# --- split setups --------------------------------------------------------------------------

# DexYCB's positions of its 10 subjects (s1) and 8 cameras (s2) in each split, and of its 20
# grasped objects (s3: the object's class id minus one); a project's own subjects and views are
# placed on that scale by their rank, so the proportions carry over (7/1/2, 6/1/1, 15/2/3).
_S1 = {6: "val", 7: "test", 8: "test"}
_S2 = {6: "val", 7: "test"}
_S3 = {3: "val", 19: "val", 7: "test", 11: "test", 15: "test"}


def _scaled(rank: int, count: int, slots: int) -> int:
    return rank * slots // max(count, 1)


def split_lists(setup: str, sequences: Sequence[tuple[str, str, Sequence[str], int | None]]
                ) -> dict[str, list[str]]:
    """DexYCB's split of a project's views into train / val / test.

    Args:
        setup: "s0" (by sequence: every fifth of a subject's sequences is held out, to val for
            the first fifth of the subjects and to test for the rest), "s1" (unseen subjects),
            "s2" (unseen camera views) or "s3" (unseen grasped objects).
        sequences: (subject, sequence name, serials in view order, grasped YCB id or None).

    Returns:
        {"train", "val", "test"}: sorted ``<subject>/<sequence>/<serial>`` lines.
    """
    if setup not in SPLIT_SETUPS:
        raise ValueError(f"split setup must be one of {', '.join(SPLIT_SETUPS)}, got {setup!r}")
    subjects = sorted({s for s, _, _, _ in sequences})
    names = {s: sorted(n for subj, n, _, _ in sequences if subj == s) for s in subjects}
    out: dict[str, list[str]] = {name: [] for name in SPLIT_NAMES}
    for subject, name, serials, grasped in sequences:
        s_rank = subjects.index(subject)
        for v, serial in enumerate(serials):
            split = "train"
            if setup == "s0" and names[subject].index(name) % 5 == 4:
                split = "val" if _scaled(s_rank, len(subjects), 10) < 2 else "test"
            elif setup == "s1":
                split = _S1.get(_scaled(s_rank, len(subjects), 10), "train")
            elif setup == "s2":
                split = _S2.get(_scaled(v, len(serials), 8), "train")
            elif setup == "s3" and grasped is not None:
                split = _S3.get(grasped - 1, "train")
            out[split].append(f"{subject}/{name}/{serial}")
    return {k: sorted(v) for k, v in out.items()}
