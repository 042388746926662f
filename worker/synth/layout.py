"""The DexYCB raw layout: calibration, object models, sequence metadata and per-camera labels.

See worker.synth.capture for the folder tree. Ground truth is kept in float64 until it is
written; npz arrays are float32 as in DexYCB.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worker.formats import dexycb
from worker.formats.dexycb import MODEL_MTL, MODEL_OBJ, MODEL_TEXTURE
from worker.formats.files import encode_image, write_npz, write_yaml
from worker.geometry.cameras import project_camera_points
from worker.geometry.mesh_io import write_mtl, write_obj
from worker.geometry.transforms import (
    compose_poses,
    invert_pose,
    transform_points,
    transform_pose_m,
)
from worker.synth.scene import CameraSpec
from worker.synth.shapes import ObjectSpec, object_mesh


@dataclass(frozen=True)
class LabelSet:
    """Ground truth of a sequence in one frame of reference (F frames, K objects).

    Attributes:
        pose_y: (F, K, 3, 4) object-to-frame poses, metres.
        pose_m: (F, 51) MANO pose_m (PCA form) in the frame.
        joints: (F, 21, 3) hand joints in DexYCB order, metres.
    """

    pose_y: np.ndarray
    pose_m: np.ndarray
    joints: np.ndarray


def camera_labels(world: LabelSet, T_cam_to_world: np.ndarray, cam: CameraSpec,
                  root_joint: np.ndarray) -> dict[str, np.ndarray]:
    """Per-frame DexYCB label arrays (leading dim F) in one camera's frame, float32.

    Returns pose_y (F, K, 3, 4), pose_m (F, 1, 51), joint_3d (F, 1, 21, 3) metres and
    joint_2d (F, 1, 21, 2) pixels (projected with the camera's distortion). ``seg`` is added
    by the renderer.
    """
    w2c = invert_pose(T_cam_to_world)
    joint_3d = transform_points(w2c, world.joints)
    labels = {
        dexycb.POSE_Y: compose_poses(w2c, world.pose_y),
        dexycb.POSE_M: transform_pose_m(world.pose_m, w2c, root_joint)[:, None],
        dexycb.JOINT_3D: joint_3d[:, None],
        dexycb.JOINT_2D: project_camera_points(joint_3d, cam.K, cam.dist)[:, None],
    }
    return {k: v.astype(np.float32) for k, v in labels.items()}


def write_calibration(root: Path, cams: list[CameraSpec], extrinsics: list[np.ndarray],
                      names: dict[str, str], betas: np.ndarray, width: int, height: int) -> None:
    """calibration/: per-camera intrinsics (depth is aligned to colour, so both are the colour
    camera's), camera-to-world extrinsics with the master serial and the table's frame (as
    DexYCB's ``apriltag``), and the subject's betas."""
    (root / dexycb.INTRINSICS_DIR).mkdir(parents=True)
    for cam in cams:
        K = cam.K
        write_yaml(root / dexycb.intrinsics_file(cam.serial, width, height),
                   dexycb.intrinsics_doc(K[0, 0], K[1, 1], K[0, 2], K[1, 2], width, height,
                                         cam.dist))
    extr_path = root / dexycb.extrinsics_file(names["extrinsics"])
    extr_path.parent.mkdir()
    table_to_world = invert_pose(cams[0].T_cam_to_table)  # the world is the master camera's
    write_yaml(extr_path, dexycb.extrinsics_doc(
        {c.serial: T for c, T in zip(cams, extrinsics, strict=True)}, cams[0].serial,
        tag=table_to_world))
    mano_path = root / dexycb.mano_file(names["mano_calib"])
    mano_path.parent.mkdir()
    write_yaml(mano_path, dexycb.mano_doc(betas))


def write_models(root: Path, specs: list[ObjectSpec], textures: list[np.ndarray]) -> None:
    """models/<ycb name>/: textured OBJ, its material library and texture image, metres."""
    for spec, texture in zip(specs, textures, strict=True):
        folder = root / dexycb.model_dir(spec.name)
        folder.mkdir(parents=True)
        write_obj(folder / MODEL_OBJ, object_mesh(spec), mtl_name=MODEL_MTL)
        write_mtl(folder / MODEL_MTL, MODEL_TEXTURE)
        (folder / MODEL_TEXTURE).write_bytes(encode_image(".png", texture))


def write_sequence_files(root: Path, names: dict[str, str], serials: list[str],
                         ycb_ids: list[int], grasp_ind: int, world: LabelSet, frames: int) -> Path:
    """<subject>/<sequence>/meta.yml and pose.npz (world frame); returns the sequence folder."""
    seq = root / dexycb.sequence_dir(names["subject"], names["sequence"])
    seq.mkdir(parents=True)
    write_yaml(seq / dexycb.META_FILE, dexycb.meta_doc(
        serials, frames, ycb_ids, grasp_ind, ["right"], [names["mano_calib"]],
        names["extrinsics"]))
    write_npz(seq / dexycb.POSE_FILE, dexycb.pose_arrays(world.pose_y, world.pose_m[:, None]))
    return seq
