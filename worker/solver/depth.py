"""The depth term: merged point clouds, their closest points on the union of meshes.

Each view's depth image (uint16 mm along the camera's z, aligned to colour) becomes world
points through the colour camera's undistorted rays; the views are merged, cropped to the
workspace box and to the points within `margin` of a current mesh, and each point is matched to
its closest surface point on the union of meshes (AABB trees, see `mesh_query`). The match is
kept as (mesh, triangle, barycentric coordinates); the residual p - sum_k b_k V_k(pose) is then
differentiable in the pose through the triangle's vertices, which is the gradient of the squared
distance (the sign of a signed distance cancels in its square).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.cameras import CameraModel, pixels_to_rays
from worker.solver.mesh_query import AABBTree


class DepthClouds:
    """Per-frame merged world point clouds from V depth streams (subsampled by `stride`)."""

    def __init__(self, cameras: list[CameraModel], depth: list[np.ndarray | None],
                 stride: int) -> None:
        self.views = []
        for camera, images in zip(cameras, depth, strict=True):
            if images is None:
                continue
            ys, xs = np.mgrid[0:images.shape[1]:stride, 0:images.shape[2]:stride]
            pixels = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
            rays = pixels_to_rays(pixels, camera.K, camera.dist)
            self.views.append((images, ys.ravel(), xs.ravel(), rays, camera.T_cam_to_world))

    def __bool__(self) -> bool:
        return bool(self.views)

    def points(self, frame: int) -> np.ndarray:
        """(N, 3) world points, metres, of all views at `frame` (pixels without depth dropped)."""
        clouds = []
        for images, ys, xs, rays, T in self.views:
            z = images[frame][ys, xs].astype(np.float64) * 1e-3
            keep = z > 0
            cam = rays[keep] * z[keep, None]
            clouds.append(cam @ T[:, :3].T + T[:, 3])
        return np.concatenate(clouds) if clouds else np.zeros((0, 3))


@dataclass
class Matches:
    """Depth points matched to meshes: points (N, 3) world m; mesh (N,) index; face (N,);
    bary (N, 3); dist (N,) metres at the time of matching."""

    points: np.ndarray
    mesh: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    dist: np.ndarray


def crop_to_boxes(points: np.ndarray, boxes: list[tuple[np.ndarray, np.ndarray]],
                  margin: float) -> np.ndarray:
    """Points (N, 3) inside any box (lo (3,), hi (3,)) grown by `margin` metres."""
    keep = np.zeros(len(points), dtype=bool)
    for lo, hi in boxes:
        keep |= ((points >= lo - margin) & (points <= hi + margin)).all(axis=1)
    return points[keep]


def match_points(points: np.ndarray, trees: list[AABBTree],
                 poses: list[np.ndarray | None], margin: float) -> Matches:
    """Closest surface point on the union of meshes for each point (N, 3) world.

    trees[i] is built in mesh i's own frame; poses[i] (3, 4) maps it to world (None: the tree
    is already in world coordinates). Points farther than `margin` from every mesh are dropped.
    """
    n = len(points)
    best = np.full(n, np.inf)
    mesh = np.full(n, -1)
    face = np.zeros(n, dtype=np.int64)
    bary = np.zeros((n, 3))
    for i, (tree, pose) in enumerate(zip(trees, poses, strict=True)):
        local = points if pose is None else (points - pose[:, 3]) @ pose[:, :3]
        lo, hi = tree.lo[0] - margin, tree.hi[0] + margin
        near = np.flatnonzero(((local >= lo) & (local <= hi)).all(axis=1))
        if near.size == 0:
            continue
        d, f, b = tree.closest(local[near])
        better = d < best[near]
        idx = near[better]
        best[idx], mesh[idx], face[idx], bary[idx] = d[better], i, f[better], b[better]
    keep = best <= margin
    return Matches(points[keep], mesh[keep], face[keep], bary[keep], best[keep])


def subsample(points: np.ndarray, limit: int, rng: np.random.Generator) -> np.ndarray:
    """At most `limit` of points (N, 3), drawn without replacement."""
    if len(points) <= limit:
        return points
    return points[rng.choice(len(points), limit, replace=False)]
