"""Whether a surface point of a solved object shows in a view: hidden by the scene's meshes
(a ray cast towards the camera) or by the depth camera (a nearer reading all around its pixel);
and how much of an object shows in each frame. World metres, image px."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from worker.assist.visibility import DepthMaps
from worker.geometry.cameras import CameraModel
from worker.quality.solved_scene import SolvedObjects
from worker.solver.mesh_query import closest_on_triangles

# A mesh nearer than the point by this much along its ray hides it (metres): the point lies on
# a face, and the face it lies on must not hide it.
MESH_MARGIN_M = 0.004
# The depth camera hides a point when it reads a surface this much nearer (metres): a hand
# over the object reads 1-3 cm nearer; sensor noise at 0.7 m is ~1 mm.
DEPTH_MARGIN_M = 0.012
# The depth camera hides a point only when every reading within this many px of its pixel
# (a square) is that much nearer: a rig whose calibration or depth registration is a few
# pixels off (a camera turned by 0.5 degrees or moved by 5 mm shows 3-8 px, less what the
# view's offset takes out; depth images 2-3 px off their colour images) reads a point near an
# edge, or on a slope of its own surface, at a neighbouring pixel that is nearer, while a
# hand over the point covers the whole square.
DEPTH_WINDOW_PX = 3
# A depth reading within this distance (m) of a solved object's surface is that object: a hand
# over an object reads at least 17 mm off every surface (a finger's thickness), a camera turned
# 0.5 degrees and moved 5 mm reads its objects 6-10 mm off their model.
SEEN_SURFACE_M = 0.012
_WINDOW = np.array([(dy, dx) for dy in range(-DEPTH_WINDOW_PX, DEPTH_WINDOW_PX + 1)
                    for dx in range(-DEPTH_WINDOW_PX, DEPTH_WINDOW_PX + 1)])
# A label that marks none of its landmarks visible anywhere has nothing to anchor; it is judged
# by the object itself: a frame shows the object when at least SHOWN_SHARE of SHOWN_SAMPLES
# surface points (its vertices, evenly taken) are in view, about a fifth of the side facing
# the camera, enough for a careful worker to place a landmark. An object that never shows in
# the view (out of the image, behind another object or the hand) is rightly labelled hidden.
SHOWN_SHARE = 0.1
SHOWN_SAMPLES = 64


# Pixels (..., 2) of the camera model -> where the camera truly shows them.
PixelMap = Callable[[np.ndarray], np.ndarray]


def ray_hits(origin: np.ndarray, dirs: np.ndarray,
             tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit of each ray with the triangles (Moller-Trumbore).

    origin (3,), dirs (R, 3) unit, tri (M, 3, 3) world metres. Returns (R,) distance along the
    ray (inf where none) and (R,) the face hit (-1 where none).
    """
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(dirs[:, None, :], e2[None])
    det = np.einsum("mk,rmk->rm", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
    s = origin - tri[:, 0]
    u = np.einsum("mk,rmk->rm", s, p) * inv
    q = np.cross(s, e1)
    v = np.einsum("rk,mk->rm", dirs, q) * inv
    t = np.einsum("mk,mk->m", e2, q)[None] * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & np.isfinite(t)
    dist = np.where(hit, t, np.inf)
    face = np.argmin(dist, axis=1)
    best = dist[np.arange(len(dirs)), face]
    return best, np.where(np.isfinite(best), face, -1)


def point_visibility(camera: CameraModel, world: np.ndarray, scene: SolvedObjects,
                     depth: DepthMaps | None, image_map: PixelMap | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(F,) whether the world track (F, 3) shows in the view: in front, inside the image, no
    solved mesh nearer along its ray, and no depth reading well in front of it; and (F,) the
    shown frames where the point sits at the edge of something in front of it
    (``at_depth_edge``): its visibility there says nothing of the worker. image_map: where the
    camera truly shows a projected pixel (a camera offset, worker.quality.view_offset), so the
    depth map is read where the point is seen."""
    frames = len(world)
    pix = camera.project(world)
    if image_map is not None:
        pix = image_map(pix)
    z = camera.depth_of(world)
    inside = np.isfinite(z) & (z > 0) & (pix[:, 0] >= 0) & (pix[:, 0] < camera.width) \
        & (pix[:, 1] >= 0) & (pix[:, 1] < camera.height)
    shown = inside.copy()
    origin = camera.T_cam_to_world[:, 3]
    for f in np.flatnonzero(inside):
        offset = world[f] - origin
        reach = float(np.linalg.norm(offset))
        dirs = (offset / reach)[None]
        for index in range(len(scene.vertices)):
            tri = scene.triangles(index, int(f))
            if np.isfinite(tri).all() and ray_hits(origin, dirs, tri)[0][0] < reach - MESH_MARGIN_M:
                shown[f] = False
                break
    edge = np.zeros(frames, bool)
    if depth is not None:
        at = np.flatnonzero(shown)
        if at.size:
            hidden, near_edge = depth_cover(depth, camera, at, pix[at], z[at])
            own = at[hidden][_reads_a_mesh(depth, camera, at[hidden], world[at[hidden]],
                                           pix[at[hidden]], scene)]
            edge[at[near_edge]] = True
            edge[own] = True
            shown[at[hidden]] = False
            shown[own] = True
    assert shown.shape == (frames,)
    return shown, edge


def _reads_a_mesh(depth: DepthMaps, camera: CameraModel, frames: np.ndarray, world: np.ndarray,
                  pix: np.ndarray, scene: SolvedObjects) -> np.ndarray:
    """(N,) whether the depth reading in front of each point (world (N, 3); its pixel (N, 2)
    where the camera shows it) lies on a solved object's own surface (within SEEN_SURFACE_M):
    the meshes' own occlusion is the ray test's to judge, and a camera whose pose is a little
    off reads, near an edge, the object's near face in front of the point its model puts on a
    face behind; the depth test hides a point only behind what no mesh models (a hand)."""
    out = np.zeros(len(frames), bool)
    if not len(frames):
        return out
    reading = readings_m(depth, camera, frames, pix)
    for i, f in enumerate(frames):
        if not np.isfinite(reading[i]):
            continue
        seen = at_reading(camera, world[i], float(reading[i]))
        for index in range(len(scene.vertices)):
            tri = scene.triangles(index, int(f))
            if np.isfinite(tri).all() and surface_nearest(seen, tri)[1] <= SEEN_SURFACE_M:
                out[i] = True
                break
    return out


def readings_m(depth: DepthMaps, camera: CameraModel, frames: np.ndarray,
               pix: np.ndarray) -> np.ndarray:
    """(N,) the depth camera's reading (m) at each pixel (N, 2) of frames (N,) int; NaN where
    it reads nothing or the pixel is outside the image."""
    rows, cols = np.rint(pix[:, 1]).astype(int), np.rint(pix[:, 0]).astype(int)
    inside = (rows >= 0) & (rows < camera.height) & (cols >= 0) & (cols < camera.width)
    reading = depth[(frames, rows.clip(0, camera.height - 1),
                     cols.clip(0, camera.width - 1))] / 1000.0
    return np.where(inside & (reading > 0), reading, np.nan)


def at_reading(camera: CameraModel, world: np.ndarray, reading: float) -> np.ndarray:
    """The point (3,) on the camera's ray through world point (3,) at depth ``reading`` (m):
    where the depth camera puts what it sees there."""
    origin = camera.T_cam_to_world[:, 3]
    return origin + (world - origin) * (reading / camera.depth_of(world))


def surface_nearest(point: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, float]:
    """The nearest point (3,) to point (3,) on triangles (M, 3, 3), and its distance (m)."""
    bary = closest_on_triangles(np.broadcast_to(point, (len(tri), 3)), tri)
    nearest = np.einsum("mk,mkd->md", bary, tri)
    gaps = np.linalg.norm(nearest - point, axis=1)
    best = int(np.argmin(gaps))
    return nearest[best], float(gaps[best])


def depth_cover(depth: DepthMaps, camera: CameraModel, frames: np.ndarray, pix: np.ndarray,
                z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """From one read of the square of DEPTH_WINDOW_PX around each point's pixel: (N,) whether
    the point is ``covered`` and (N,) whether it is ``at_depth_edge``. frames (N,) int; pix
    (N, 2) px; z (N,) metres."""
    rows = np.rint(pix[:, 1]).astype(int)[:, None] + _WINDOW[:, 0]
    cols = np.rint(pix[:, 0]).astype(int)[:, None] + _WINDOW[:, 1]
    reading = depth[(np.broadcast_to(frames[:, None], rows.shape),
                     rows.clip(0, camera.height - 1), cols.clip(0, camera.width - 1))] / 1000.0
    read = reading > 0
    nearer = read & (z[:, None] - reading > DEPTH_MARGIN_M)
    hidden = nearer[:, len(_WINDOW) // 2] & (nearer | ~read).all(axis=1)
    return hidden, nearer.any(axis=1) & ~hidden


def covered(depth: DepthMaps, camera: CameraModel, frames: np.ndarray, pix: np.ndarray,
            z: np.ndarray) -> np.ndarray:
    """(N,) whether the depth camera reads something well in front of each point: the reading
    at its pixel and every other within DEPTH_WINDOW_PX (those with a reading) more than
    DEPTH_MARGIN_M nearer than its depth. frames (N,) int; pix (N, 2) px; z (N,) metres."""
    return depth_cover(depth, camera, frames, pix, z)[0]


def at_depth_edge(depth: DepthMaps, camera: CameraModel, frames: np.ndarray, pix: np.ndarray,
                  z: np.ndarray) -> np.ndarray:
    """(N,) whether something in front of each point covers part of the square around its
    pixel but not the point (``covered``): the edge of a hand or another object, where a rig
    a few pixels off cannot say which side the point is on."""
    return depth_cover(depth, camera, frames, pix, z)[1]


def object_shown(camera: CameraModel, scene: SolvedObjects, target: int,
                 depth: DepthMaps | None) -> np.ndarray:
    """(F,) share of object ``target``'s sampled surface points (SHOWN_SAMPLES vertices) the
    view shows, by the rules of point_visibility (in the image, no solved mesh nearer along the
    ray, no depth reading well in front); NaN where the pose is unknown."""
    vertices = scene.vertices[target]
    samples = vertices[np.unique(np.linspace(0, len(vertices) - 1,
                                             min(SHOWN_SAMPLES, len(vertices))).astype(int))]
    origin = camera.T_cam_to_world[:, 3]
    out = np.full(scene.poses.shape[1], np.nan)
    for f in range(scene.poses.shape[1]):
        pose = scene.poses[target, f]
        if not np.isfinite(pose).all():
            continue
        world = samples @ pose[:, :3].T + pose[:, 3]
        pix, z = camera.project(world), camera.depth_of(world)
        shown = np.isfinite(z) & (z > 0) & (pix[:, 0] >= 0) & (pix[:, 0] < camera.width) \
            & (pix[:, 1] >= 0) & (pix[:, 1] < camera.height)
        reach = np.linalg.norm(world - origin, axis=1)
        dirs = (world - origin) / reach[:, None]
        for index in range(len(scene.vertices)):
            tri = scene.triangles(index, f)
            if shown.any() and np.isfinite(tri).all():
                shown &= ~(ray_hits(origin, dirs, tri)[0] < reach - MESH_MARGIN_M)
        at = np.flatnonzero(shown)
        if depth is not None and at.size:
            shown[at[covered(depth, camera, np.full(at.size, f), pix[at], z[at])]] = False
        out[f] = shown.mean()
    return out
