"""A synthetic rig for the rig-health tests: 8 cameras in a ring around a moving 21-point
cloud (a hand-sized set of tracks) above a tilted plane with three spheres, and the exact
depth maps each camera sees of that scene (uint16 mm). Known answers; faults are applied to
copies of the cameras, tracks and depth maps in the tests."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at, pixels_to_rays
from worker.geometry.transforms import axis_angle_to_matrix, make_pose

WIDTH, HEIGHT = 320, 240
FOCAL = 310.0
# The scene: a plane through PLANE_POINT with normal PLANE_NORMAL, and spheres (centre, radius).
PLANE_POINT = np.array([0.0, 0.0, -0.05])
PLANE_NORMAL = np.array([0.15, -0.1, 1.0]) / np.linalg.norm([0.15, -0.1, 1.0])
SPHERES = [(np.array([0.12, 0.05, 0.0]), 0.05), (np.array([-0.1, -0.08, 0.02]), 0.06),
           (np.array([0.0, 0.15, -0.01]), 0.04)]


@dataclass
class RigScene:
    """cameras (V), keypoints (V, F, P, 2) px, visible (V, F, P), depth V x (F, H, W) mm,
    color V x {frame: (H, W, 3) uint8} of three frames, points (F, P, 3) world metres."""

    cameras: list[CameraModel]
    keypoints: np.ndarray
    visible: np.ndarray
    depth: list[np.ndarray]
    color: list[dict[int, np.ndarray]]
    points: np.ndarray


def ring_cameras(views: int = 8) -> list[CameraModel]:
    """Views on a ring 0.7 m from the origin, 0.45 m up, all looking at the origin; view 0 is
    moved to the world frame's identity by expressing everything in its frame."""
    K = intrinsics_matrix(FOCAL, FOCAL, WIDTH / 2, HEIGHT / 2)
    poses = []
    for v in range(views):
        a = 2 * np.pi * v / views
        eye = np.array([0.55 * np.cos(a), 0.55 * np.sin(a), 0.45])
        poses.append(look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0])))
    return [CameraModel(K, np.zeros(5), p, WIDTH, HEIGHT) for p in poses]


def moving_points(frames: int, rng: np.random.Generator) -> np.ndarray:
    """(F, 21, 3) metres: a 21-point cloud (10 cm across) that turns and travels about 35 cm
    over the clip (1-2 cm a frame, as a reaching hand), 8-18 cm above the plane."""
    base = rng.uniform([-0.05, -0.05, 0.10], [0.05, 0.05, 0.16], (21, 3))
    t = np.linspace(0.0, 1.0, frames)
    out = np.empty((frames, 21, 3))
    for f, s in enumerate(t):
        rot = axis_angle_to_matrix(np.array([0.3, -0.2, 1.0]) * 1.5 * s)
        centre = np.array([0.12 * np.sin(6 * s), 0.2 * s - 0.1, 0.03 * np.cos(4 * s)])
        out[f] = (base - base.mean(0)) @ rot.T + base.mean(0) + centre
    return out


def depth_map(camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) uint16 mm: the nearest of the plane and the spheres along every pixel's ray,
    and (H, W, 3) uint8 colour: each surface its own grey (the spheres' outlines are edges
    in both)."""
    u, v = np.meshgrid(np.arange(WIDTH, dtype=float), np.arange(HEIGHT, dtype=float))
    rays_cam = pixels_to_rays(np.stack([u, v], -1), camera.K, camera.dist)
    rot, centre = camera.T_cam_to_world[:, :3], camera.T_cam_to_world[:, 3]
    rays = rays_cam @ rot.T  # world directions with camera z = 1
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (PLANE_POINT - centre) @ PLANE_NORMAL / (rays @ PLANE_NORMAL)
    z = np.where(z > 0, z, np.inf)
    grey = np.full(z.shape, 70.0)
    for k, (c, r) in enumerate(SPHERES):
        oc = centre - c
        a = np.einsum("hwi,hwi->hw", rays, rays)
        b = 2 * rays @ oc
        disc = b * b - 4 * a * (oc @ oc - r * r)
        hit = (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a)
        front = (disc > 0) & (hit > 0) & (hit < z)
        z = np.where(front, hit, z)
        grey = np.where(front, 140.0 + 40.0 * k, grey)
    depth = np.where(np.isfinite(z), np.rint(z * 1000), 0).astype(np.uint16)
    return depth, np.repeat(grey.astype(np.uint8)[..., None], 3, axis=2)


def make_scene(frames: int = 20, noise_px: float = 1.5, seed: int = 0,
               views: int = 8) -> RigScene:
    rng = np.random.default_rng(seed)
    cameras = ring_cameras(views)
    points = moving_points(frames, rng)
    keypoints = np.stack([c.project(points) for c in cameras])
    keypoints += rng.normal(0.0, noise_px, keypoints.shape)
    inside = (keypoints[..., 0] >= 0) & (keypoints[..., 0] < WIDTH) & \
        (keypoints[..., 1] >= 0) & (keypoints[..., 1] < HEIGHT)
    visible = inside & (rng.random(inside.shape) > 0.15)
    maps = [depth_map(c) for c in cameras]
    depth = [np.repeat(d[None], frames, axis=0) for d, _ in maps]
    color = [dict.fromkeys((0, frames // 2, frames - 1), c) for _, c in maps]
    return RigScene(cameras, keypoints, visible, depth, color, points)


def perturbed(camera: CameraModel, deg: float, mm: float, rng: np.random.Generator
              ) -> CameraModel:
    """The camera rotated by ``deg`` about a random axis and moved ``mm`` in a random
    direction (its calibration is now wrong by that much)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    move = rng.normal(size=3)
    move /= np.linalg.norm(move)
    rot = axis_angle_to_matrix(axis * np.radians(deg)) @ camera.T_cam_to_world[:, :3]
    return replace(camera, T_cam_to_world=make_pose(rot, camera.T_cam_to_world[:, 3]
                                                    + move * mm / 1000.0))


def one_frame_late(scene: RigScene, view: int) -> None:
    """View ``view`` shows at frame f what the others show at f - 1 (labels and depth)."""
    scene.keypoints[view, 1:] = scene.keypoints[view, :-1].copy()
    scene.visible[view, 1:] = scene.visible[view, :-1].copy()
    scene.visible[view, 0] = False
