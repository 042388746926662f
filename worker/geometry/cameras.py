"""Pinhole cameras with OpenCV's distortion model, on batched float64 arrays.

Conventions (written down once for the whole project):

- image pixels: x to the right, y down, the centre of the top-left pixel at (0, 0), as OpenCV;
- camera frame (OpenCV): x right, y down, z forward along the optical axis, metres;
- extrinsics are ``T_cam_to_world`` (3, 4): ``x_world = R x_cam + t``, metres;
- intrinsics ``K`` (3, 3) = ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` in pixels (OpenCV's own
  ``projectPoints`` ignores the skew ``s``; it is honoured here and is 0 for every capture);
- distortion ``dist`` (5,) = ``(k1, k2, p1, p2, k3)``, OpenCV's radial-tangential model applied
  to normalised coordinates ``(X/Z, Y/Z)`` (worker.geometry.distortion, its one implementation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.distortion import distort, undistort
from worker.geometry.transforms import make_pose


def _as_points(name: str, points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim < 1 or points.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3), got {points.shape}")
    return points


def _as_pose(name: str, pose: np.ndarray) -> np.ndarray:
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (3, 4):
        raise ValueError(f"{name} must have shape (3, 4), got {pose.shape}")
    return pose


def _as_intrinsics(K: np.ndarray) -> np.ndarray:
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise ValueError(f"K must have shape (3, 3), got {K.shape}")
    return K


def _as_dist(dist: np.ndarray | None) -> np.ndarray | None:
    if dist is None:
        return None
    dist = np.asarray(dist, dtype=np.float64)
    if dist.shape in ((1, 5), (5, 1)):
        dist = dist.reshape(5)
    if dist.shape != (5,):
        raise ValueError(f"dist must have shape (5,) as (k1, k2, p1, p2, k3), got {dist.shape}")
    return dist


def world_to_camera(points_world: np.ndarray, T_cam_to_world: np.ndarray) -> np.ndarray:
    """World points (..., 3) metres -> the camera's frame (..., 3) metres."""
    points_world = _as_points("points_world", points_world)
    T = _as_pose("T_cam_to_world", T_cam_to_world)
    rot, trans = T[:, :3], T[:, 3]
    return (points_world - trans) @ rot


def camera_to_world(points_cam: np.ndarray, T_cam_to_world: np.ndarray) -> np.ndarray:
    """Camera-frame points (..., 3) metres -> world frame (..., 3) metres."""
    points_cam = _as_points("points_cam", points_cam)
    T = _as_pose("T_cam_to_world", T_cam_to_world)
    return points_cam @ T[:, :3].T + T[:, 3]


def distort_normalized(xy: np.ndarray, dist: np.ndarray | None) -> np.ndarray:
    """Apply OpenCV's (k1, k2, p1, p2, k3) model to normalised coordinates (..., 2) -> (..., 2)."""
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim < 1 or xy.shape[-1] != 2:
        raise ValueError(f"xy must have shape (..., 2), got {xy.shape}")
    dist = _as_dist(dist)
    if dist is None:
        return xy
    xd, yd = distort(xy[..., 0], xy[..., 1], dist)
    return np.stack([xd, yd], axis=-1)


def project_camera_points(
    points_cam: np.ndarray, K: np.ndarray, dist: np.ndarray | None = None
) -> np.ndarray:
    """Camera-frame points (..., 3) metres -> pixels (..., 2) (x right, y down).

    Points with z <= 0 (behind the camera) give meaningless pixels, as in OpenCV; callers that
    care must test ``points_cam[..., 2] > 0`` themselves.
    """
    points_cam = _as_points("points_cam", points_cam)
    K = _as_intrinsics(K)
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = points_cam[..., :2] / points_cam[..., 2:3]
    xy = distort_normalized(xy, dist)
    u = K[0, 0] * xy[..., 0] + K[0, 1] * xy[..., 1] + K[0, 2]
    v = K[1, 1] * xy[..., 1] + K[1, 2]
    return np.stack([u, v], axis=-1)


def project_points(
    X_world: np.ndarray,
    K: np.ndarray,
    T_cam_to_world: np.ndarray,
    dist: np.ndarray | None = None,
) -> np.ndarray:
    """Project world points into a camera; matches ``cv2.projectPoints`` for zero skew.

    Args:
        X_world: (..., 3) points in the world frame, metres.
        K: (3, 3) intrinsics, pixels.
        T_cam_to_world: (3, 4) camera-to-world extrinsics, metres.
        dist: (5,) ``(k1, k2, p1, p2, k3)`` or None for an ideal pinhole.

    Returns:
        (..., 2) pixel coordinates, x right and y down.
    """
    X_world = _as_points("X_world", X_world)
    return project_camera_points(world_to_camera(X_world, T_cam_to_world), K, dist)


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """OpenCV camera at ``eye`` looking at ``target``: returns ``T_cam_to_world`` (3, 4).

    The camera's z axis points from ``eye`` to ``target``, its y axis (image down) points
    against ``up`` as far as it can, and x = y x z completes a right-handed frame, so ``up``
    appears upward in the image. All inputs (3,) in world metres; ``up`` need not be unit.
    """
    eye, target, up = (np.asarray(a, dtype=np.float64) for a in (eye, target, up))
    for name, a in (("eye", eye), ("target", target), ("up", up)):
        if a.shape != (3,):
            raise ValueError(f"{name} must have shape (3,), got {a.shape}")
    forward = target - eye
    norm = np.linalg.norm(forward)
    if norm < 1e-12:
        raise ValueError("eye and target coincide")
    z_axis = forward / norm
    x_axis = np.cross(z_axis, up)
    x_norm = np.linalg.norm(x_axis)
    if x_norm < 1e-9 * max(float(np.linalg.norm(up)), 1e-300):
        raise ValueError("up is parallel to the viewing direction")
    x_axis /= x_norm
    y_axis = np.cross(z_axis, x_axis)
    return make_pose(np.stack([x_axis, y_axis, z_axis], axis=1), eye)


def intrinsics_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """Build K (3, 3) from focal lengths and principal point, pixels."""
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def undistort_normalized(xy_distorted: np.ndarray, dist: np.ndarray | None,
                         iterations: int = 30) -> np.ndarray:
    """Invert :func:`distort_normalized` by fixed-point iteration, as OpenCV does.

    Args:
        xy_distorted: (..., 2) distorted normalised coordinates.
        dist: (5,) ``(k1, k2, p1, p2, k3)`` or None (identity).
        iterations: fixed-point steps; 30 reach ~1e-12 for the mild distortion of RGB-D cameras.

    Returns:
        (..., 2) undistorted normalised coordinates ``(X/Z, Y/Z)``.
    """
    xy_d = np.asarray(xy_distorted, dtype=np.float64)
    if xy_d.ndim < 1 or xy_d.shape[-1] != 2:
        raise ValueError(f"xy_distorted must have shape (..., 2), got {xy_d.shape}")
    dist = _as_dist(dist)
    if dist is None:
        return xy_d.copy()
    x, y = undistort(xy_d[..., 0], xy_d[..., 1], dist, iterations)
    return np.stack([x, y], axis=-1)


def pixels_to_rays(pixels: np.ndarray, K: np.ndarray, dist: np.ndarray | None = None) -> np.ndarray:
    """Pixels (..., 2) -> camera-frame viewing rays (..., 3) with z = 1 (undistorted)."""
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.ndim < 1 or pixels.shape[-1] != 2:
        raise ValueError(f"pixels must have shape (..., 2), got {pixels.shape}")
    K = _as_intrinsics(K)
    y = (pixels[..., 1] - K[1, 2]) / K[1, 1]
    x = (pixels[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    xy = undistort_normalized(np.stack([x, y], axis=-1), dist)
    return np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)


@dataclass(frozen=True)
class CameraModel:
    """One calibrated view as the worker packages take it.

    K: (3, 3) intrinsics, pixels. dist: (5,) OpenCV ``(k1, k2, p1, p2, k3)`` or None.
    T_cam_to_world: (3, 4) camera-to-world extrinsics, metres. width, height: image size, pixels.
    """

    K: np.ndarray
    dist: np.ndarray | None
    T_cam_to_world: np.ndarray
    width: int
    height: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "K", _as_intrinsics(self.K))
        object.__setattr__(self, "dist", _as_dist(self.dist))
        object.__setattr__(self, "T_cam_to_world", _as_pose("T_cam_to_world", self.T_cam_to_world))

    def project(self, X_world: np.ndarray) -> np.ndarray:
        """World points (..., 3) metres -> pixels (..., 2)."""
        return project_points(X_world, self.K, self.T_cam_to_world, self.dist)

    def depth_of(self, X_world: np.ndarray) -> np.ndarray:
        """Camera-frame z (...,) of world points (..., 3), metres (<= 0: behind the camera)."""
        return world_to_camera(X_world, self.T_cam_to_world)[..., 2]
