"""The DexYCB raw layout: calibration, object models, sequence metadata and per-camera labels.

See worker.synth.capture for the folder tree. Ground truth is kept in float64 until it is
written; npz arrays are float32 as in DexYCB.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worker.geometry.cameras import project_camera_points
from worker.geometry.mesh_io import write_mtl, write_obj
from worker.geometry.transforms import (
    compose_poses,
    invert_pose,
    matrix_to_quaternion,
    transform_points,
    transform_pose_m,
)
from worker.synth.scene import CameraSpec
from worker.synth.shapes import ObjectSpec, object_mesh
from worker.synth.writer import encode_image, write_npz, write_yaml

MODEL_OBJ = "textured_simple.obj"
MODEL_MTL = "textured_simple.obj.mtl"
MODEL_TEXTURE = "texture_map.png"


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
        "pose_y": compose_poses(w2c, world.pose_y),
        "pose_m": transform_pose_m(world.pose_m, w2c, root_joint)[:, None],
        "joint_3d": joint_3d[:, None],
        "joint_2d": project_camera_points(joint_3d, cam.K, cam.dist)[:, None],
    }
    return {k: v.astype(np.float32) for k, v in labels.items()}


def _intrinsics_entry(cam: CameraSpec, width: int, height: int) -> dict:
    K = cam.K
    return {"fx": float(K[0, 0]), "fy": float(K[1, 1]), "ppx": float(K[0, 2]),
            "ppy": float(K[1, 2]), "width": width, "height": height,
            "coeffs": [float(c) for c in cam.dist]}


def write_calibration(root: Path, cams: list[CameraSpec], extrinsics: list[np.ndarray],
                      names: dict[str, str], betas: np.ndarray, width: int, height: int) -> None:
    """calibration/: per-camera intrinsics (depth is aligned to colour, so both are the colour
    camera's), camera-to-world extrinsics with the master serial, and the subject's betas."""
    calib = root / "calibration"
    (calib / "intrinsics").mkdir(parents=True)
    for cam in cams:
        entry = _intrinsics_entry(cam, width, height)
        write_yaml(calib / "intrinsics" / f"{cam.serial}_{width}x{height}.yml",
                   {"color": entry, "depth": dict(entry)})
    extr_dir = calib / f"extrinsics_{names['extrinsics']}"
    extr_dir.mkdir()
    write_yaml(extr_dir / "extrinsics.yml", {
        "extrinsics": {c.serial: [float(x) for x in T.reshape(-1)]
                       for c, T in zip(cams, extrinsics, strict=True)},
        "master": cams[0].serial,
    })
    mano_dir = calib / f"mano_{names['mano_calib']}"
    mano_dir.mkdir()
    write_yaml(mano_dir / "mano.yml", {"betas": [float(b) for b in betas]})


def write_models(root: Path, specs: list[ObjectSpec], textures: list[np.ndarray]) -> None:
    """models/<ycb name>/: textured OBJ, its material library and texture image, metres."""
    for spec, texture in zip(specs, textures, strict=True):
        folder = root / "models" / spec.name
        folder.mkdir(parents=True)
        write_obj(folder / MODEL_OBJ, object_mesh(spec), mtl_name=MODEL_MTL)
        write_mtl(folder / MODEL_MTL, MODEL_TEXTURE)
        (folder / MODEL_TEXTURE).write_bytes(encode_image(".png", texture))


def write_sequence_files(root: Path, names: dict[str, str], serials: list[str],
                         ycb_ids: list[int], grasp_ind: int, world: LabelSet, frames: int) -> Path:
    """<subject>/<sequence>/meta.yml and pose.npz (world frame); returns the sequence folder."""
    seq = root / names["subject"] / names["sequence"]
    seq.mkdir(parents=True)
    write_yaml(seq / "meta.yml", {
        "serials": list(serials), "num_frames": frames, "ycb_ids": list(ycb_ids),
        "ycb_grasp_ind": grasp_ind, "mano_sides": ["right"],
        "mano_calib": [names["mano_calib"]], "extrinsics": names["extrinsics"],
    })
    quat = matrix_to_quaternion(world.pose_y[..., :3])
    pose_y = np.concatenate([quat, world.pose_y[..., 3]], axis=-1)
    write_npz(seq / "pose.npz", {"pose_y": pose_y.astype(np.float32),
                                 "pose_m": world.pose_m[:, None].astype(np.float32)})
    return seq
