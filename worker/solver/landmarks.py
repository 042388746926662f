"""Mapping each object landmark to a mesh vertex by back-projection (done once, then fixed).

A landmark is cast as a ray from its camera through its (undistorted) pixel at the first frame
where it is labelled visible; the first surface hit among all meshes in the scene decides: if
it is the landmark's object, the landmark becomes the object's vertex nearest the hit point
(not only the hit triangle's corners: on a coarse mesh the vertex meant may belong to the
neighbouring triangle of the same face); if another mesh (the hand, another object) is hit
first, the landmark is occluded there and the next visible frame is tried. Frames are world,
lengths metres, pixels x right, y down.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from worker.geometry.cameras import CameraModel, pixels_to_rays
from worker.solver.mesh_query import ray_hits

# A landmark on the silhouette can miss its object by a pixel or two of label noise; a vertex
# this close to the ray (metres) still counts as the one meant, if nothing nearer occludes it.
SILHOUETTE_TOLERANCE_M = 0.008
# How many visible frames are tried before a landmark is given up as unmappable.
MAX_TRIES = 5


def camera_ray(camera: CameraModel, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World ray (origin (3,), unit direction (3,)) through pixel xy (2,) of `camera`."""
    ray_cam = pixels_to_rays(np.asarray(xy, dtype=np.float64)[None], camera.K, camera.dist)[0]
    direction = camera.T_cam_to_world[:, :3] @ ray_cam
    return camera.T_cam_to_world[:, 3].copy(), direction / np.linalg.norm(direction)


def back_project(camera: CameraModel, xy: np.ndarray, target: tuple[np.ndarray, np.ndarray],
                 occluders: list[tuple[np.ndarray, np.ndarray]]) -> int:
    """Vertex id of `target` under pixel xy, or -1 when it is occluded or missed.

    target, occluders: (vertices (N, 3) world, faces (M, 3)) meshes posed at the frame.
    """
    origin, direction = camera_ray(camera, xy)
    vertices, faces = target
    hits = ray_hits(origin, direction, vertices[faces])
    blocked = min((ray_hits(origin, direction, v[f]).min() for v, f in occluders if len(f)),
                  default=np.inf)
    face = int(np.argmin(hits))
    if np.isfinite(hits[face]):
        if hits[face] > blocked:
            return -1
        point = origin + hits[face] * direction
        return int(np.argmin(np.linalg.norm(vertices - point, axis=1)))
    rel = vertices - origin
    along = rel @ direction
    off_ray = np.linalg.norm(rel - along[:, None] * direction, axis=1)
    near = np.flatnonzero((off_ray < SILHOUETTE_TOLERANCE_M) & (along > 0) & (along < blocked))
    if near.size == 0:
        return -1
    # The vertex nearest the ray; along a grazed edge several are, so the nearer one wins.
    best = off_ray[near].min()
    near = near[off_ray[near] <= best + 1e-6]
    return int(near[np.argmin(along[near])])


def first_visible_frames(visible: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Frames (K,) where a landmark is labelled visible with a finite position, in order."""
    ok = np.asarray(visible, dtype=bool) & np.isfinite(xy).all(axis=1)
    return np.flatnonzero(ok)


def map_landmark(camera: CameraModel, xy: np.ndarray, visible: np.ndarray,
                 scene_at: Callable[[int], tuple[tuple, list] | None],
                 ) -> tuple[int, int]:
    """(vertex id, frame used) for one landmark, or (-1, -1).

    xy: (F, 2) px, visible: (F,) bool. scene_at(frame) -> (target mesh, occluder meshes) posed
    at that frame, or None when no accurate pose is known there yet (the frame is skipped).
    """
    for frame in first_visible_frames(visible, xy)[:MAX_TRIES]:
        scene = scene_at(int(frame))
        if scene is None:
            continue
        vertex = back_project(camera, xy[frame], scene[0], scene[1])
        if vertex >= 0:
            return vertex, int(frame)
    return -1, -1
