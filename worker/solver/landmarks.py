"""Mapping each object landmark to a point of its object's surface by back-projection (done
once, then fixed).

A landmark is cast as a ray from its camera through its (undistorted) pixel at the first frame
where it is labelled visible; the first surface hit among all meshes in the scene decides: if
it is the landmark's object, the landmark becomes the hit point on that object's surface (on a
dense scanned mesh the paper's "nearest vertex" is the same point to within a millimetre; on a
coarse mesh, such as an 8-vertex box, only the hit point is right); if another mesh (the hand,
another object) is hit first, the landmark is occluded there and the next visible frame is
tried. A label just off the silhouette that misses every face maps to the object's vertex
nearest the ray. Frames are world, lengths metres, pixels x right, y down.
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

# A mesh posed at a frame: vertices (N, 3) world metres, faces (M, 3) vertex indices.
PosedMesh = tuple[np.ndarray, np.ndarray]
# The landmark's own object and the meshes that may hide it, posed at one frame.
Scene = tuple[PosedMesh, list[PosedMesh]]


def camera_ray(camera: CameraModel, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World ray (origin (3,), unit direction (3,)) through pixel xy (2,) of `camera`."""
    ray_cam = pixels_to_rays(np.asarray(xy, dtype=np.float64)[None], camera.K, camera.dist)[0]
    direction = camera.T_cam_to_world[:, :3] @ ray_cam
    return camera.T_cam_to_world[:, 3].copy(), direction / np.linalg.norm(direction)


def back_project_point(camera: CameraModel, xy: np.ndarray,
                       target: tuple[np.ndarray, np.ndarray],
                       occluders: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray | None:
    """World point (3,) of `target`'s surface under pixel xy, or None when it is occluded or
    missed: the ray's first hit on its faces, or (just off the silhouette) its nearest vertex.

    target, occluders: (vertices (N, 3) world, faces (M, 3)) meshes posed at the frame.
    """
    origin, direction = camera_ray(camera, xy)
    vertices, faces = target
    hits = ray_hits(origin, direction, vertices[faces])
    blocked = min((ray_hits(origin, direction, v[f]).min() for v, f in occluders if len(f)),
                  default=np.inf)
    face = int(np.argmin(hits))
    if np.isfinite(hits[face]):
        return None if hits[face] > blocked else origin + hits[face] * direction
    vertex = _vertex_near_ray(origin, direction, vertices, blocked)
    return None if vertex < 0 else vertices[vertex].copy()


def back_project(camera: CameraModel, xy: np.ndarray, target: tuple[np.ndarray, np.ndarray],
                 occluders: list[tuple[np.ndarray, np.ndarray]]) -> int:
    """Vertex id of `target` nearest the surface point under pixel xy (the paper's mapping),
    or -1 when it is occluded or missed. Meshes as in back_project_point."""
    point = back_project_point(camera, xy, target, occluders)
    if point is None:
        return -1
    return int(np.argmin(np.linalg.norm(target[0] - point, axis=1)))


def _vertex_near_ray(origin: np.ndarray, direction: np.ndarray, vertices: np.ndarray,
                     blocked: float) -> int:
    """The vertex nearest a ray that misses every face (a label on the silhouette), or -1."""
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
                 scene_at: Callable[[int], Scene | None],
                 ) -> tuple[np.ndarray | None, int]:
    """(world surface point (3,), frame used) for one landmark, or (None, -1).

    xy: (F, 2) px, visible: (F,) bool. scene_at(frame) -> (target mesh, occluder meshes) posed
    at that frame, or None when no accurate pose is known there yet (the frame is skipped).
    """
    for frame in first_visible_frames(visible, xy)[:MAX_TRIES]:
        scene = scene_at(int(frame))
        if scene is None:
            continue
        point = back_project_point(camera, xy[frame], scene[0], scene[1])
        if point is not None:
            return point, int(frame)
    return None, -1
