"""One camera frame as DexYCB's loader reads it: the pinhole model it assumes, the segmentation
mask, and the ``labels_%06d.npz`` arrays of a frame from world-frame poses.

DexYCB's own loader builds K from fx, fy, ppx, ppy alone and ignores distortion: a capture
written for it has pinhole images, so the export undistorts them (:func:`undistort_image`),
projects the labels with the same K (:func:`pinhole_project`) and says so in meta.yml
(:data:`worker.formats.dexycb.META_UNDISTORTED`). File names, keys and "no label" values are
:mod:`worker.formats.dexycb`'s. Pixels x right, y down; metres; K (3, 3) in pixels.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from worker.formats.dexycb import label_arrays
from worker.geometry.raster import rasterize
from worker.geometry.transforms import compose_poses, invert_pose, transform_points
from worker.geometry.transforms import transform_pose_m as move_pose_m

# --- the pinhole model DexYCB's loader assumes ----------------------------------------------

def pinhole_project(points_cam: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Camera-frame points (..., 3) metres -> pixels (..., 2) with K alone, as DexYCB's loader
    computes joint_2d (no distortion)."""
    points_cam = np.asarray(points_cam, dtype=np.float64)
    if points_cam.ndim < 1 or points_cam.shape[-1] != 3:
        raise ValueError(f"points_cam must have shape (..., 3), got {points_cam.shape}")
    K = np.asarray(K, dtype=np.float64)
    uvw = points_cam @ K.T
    with np.errstate(divide="ignore", invalid="ignore"):
        return uvw[..., :2] / uvw[..., 2:3]


def has_distortion(dist: Sequence[float] | np.ndarray | None) -> bool:
    return dist is not None and bool(np.any(np.asarray(dist, dtype=np.float64) != 0.0))


def undistort_maps(K: np.ndarray, dist: np.ndarray, width: int, height: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV remap tables (H, W) float32 from the pinhole image (same K) to the distorted one."""
    K = np.asarray(K, dtype=np.float64)
    coeffs = np.asarray(dist, dtype=np.float64).reshape(-1)
    map_x, map_y = cv2.initUndistortRectifyMap(K, coeffs, None, K, (int(width), int(height)),
                                               cv2.CV_32FC1)
    return map_x, map_y


def undistort_image(image: np.ndarray, maps: tuple[np.ndarray, np.ndarray],
                    nearest: bool = False) -> np.ndarray:
    """The pinhole image of a distorted one; ``nearest`` for depth (no blending across edges)
    and label images. Pixels that map outside the source are 0."""
    flag = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    return cv2.remap(image, maps[0], maps[1], flag, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=0)


# --- labels of one camera frame from world-frame poses --------------------------------------

def render_seg(meshes: Sequence[tuple[np.ndarray, np.ndarray, int]], K: np.ndarray, width: int,
               height: int) -> np.ndarray:
    """The (H, W) uint8 segmentation of posed meshes seen by a pinhole camera (K alone).

    meshes: (vertices (N, 3) in the camera frame, metres; faces (M, 3); seg value) each: an
    object's YCB id or dexycb.HAND_SEG_VALUE. The nearest surface wins each pixel; 0 elsewhere.
    """
    seg = np.zeros(height * width, dtype=np.uint8)
    drawn = [(np.asarray(v, np.float64), np.asarray(f, np.int64), value)
             for v, f, value in meshes if len(f) and np.isfinite(v).all()]
    if not drawn:
        return seg.reshape(height, width)
    offsets = np.cumsum([0] + [len(v) for v, _, _ in drawn[:-1]])
    vertices = np.concatenate([v for v, _, _ in drawn])
    faces = np.concatenate([f + o for (_, f, _), o in zip(drawn, offsets, strict=True)])
    values = np.concatenate([np.full(len(f), value, np.uint8) for _, f, value in drawn])
    frags = rasterize(vertices, faces, np.asarray(K, np.float64), width, height)
    seg[frags.pixels] = values[frags.tri.reshape(-1)[frags.pixels]]
    return seg.reshape(height, width)


def camera_frame_labels(T_cam_to_world: np.ndarray, K: np.ndarray, object_poses: np.ndarray,
                        pose_m: np.ndarray | None, joints: np.ndarray | None,
                        root_joint: np.ndarray | None, seg: np.ndarray) -> dict[str, np.ndarray]:
    """One camera frame's labels_%06d.npz arrays from world-frame labels.

    T_cam_to_world: (3, 4) metres. K: (3, 3) px, the pinhole intrinsics of the exported image.
    object_poses: (O, 3, 4) object-to-world (NaN: unlabelled). pose_m: (51,) world frame and
    joints (21, 3) world metres, or None / NaN where the hand is unlabelled; root_joint: (3,)
    the rest hand's root joint (MANO J0 of the subject's betas). seg: (H, W) uint8.
    joint_2d is the pinhole projection of joint_3d with K alone, as DexYCB's loader computes it.
    """
    w2c = invert_pose(np.asarray(T_cam_to_world, np.float64))
    pose_y = compose_poses(w2c, np.asarray(object_poses, np.float64))
    hand_ok = (pose_m is not None and joints is not None and root_joint is not None
               and np.isfinite(pose_m).all() and np.isfinite(joints).all())
    if not hand_ok:
        return label_arrays(seg, pose_y, None, None, None)
    assert pose_m is not None and joints is not None and root_joint is not None
    joint_3d = transform_points(w2c, np.asarray(joints, np.float64))
    cam_pose_m = move_pose_m(np.asarray(pose_m, np.float64), w2c, np.asarray(root_joint))
    return label_arrays(seg, pose_y, cam_pose_m, joint_3d, pinhole_project(joint_3d, K))
