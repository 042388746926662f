"""Whether a label's object landmarks are points a person can follow: distinct points of the
object's surface, in plain view of the camera, and shown through the clip.

The DexYCB annotators pick, per view, two distinctive landmarks that are easy to track and
visible most of the time. Once each landmark is anchored to a point of the object's surface
(worker.quality.anchored: under the solved poses, or for an object that stays where it was
placed, under its pose at import), these say what the track alone cannot:

- separation: two landmarks on one spot follow the object as well as two distinct ones (on a
  static object both score 0 px against their anchors), but fix nothing of its rotation: the
  least distance between anchored points on the surface, millimetres;
- facing: a landmark on a surface seen edge-on (the object's outline) moves off its point with
  the slightest turn and cannot be placed twice alike: the cosine between the surface normal
  at the anchored point and the direction to the camera, median over the frames it shows;
- shown: a landmark its view shows in only a few frames cannot be tracked: the share of the
  frames with a known pose in which the anchored point shows (the least over the landmarks).

Object frame in metres; world metres; one camera view.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.quality.metrics import num
from worker.quality.solved_scene import SolvedObjects


def separation_mm(points: Sequence[np.ndarray]) -> float | None:
    """Least distance between any two of the anchored points (each (3,), object frame, metres),
    millimetres; None with fewer than two."""
    if len(points) < 2:
        return None
    stacked = np.asarray(points, dtype=np.float64).reshape(len(points), 3)
    gaps = np.linalg.norm(stacked[:, None] - stacked[None], axis=2)
    return num(1000.0 * gaps[np.triu_indices(len(points), 1)].min(), 2)


def surface_normal(point: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(3,) unit normal of the face nearest ``point`` (3,) (object frame, metres), the face an
    anchored point lies on; vertices (N, 3), faces (M, 3)."""
    tri = vertices[faces]
    a, u, v = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    normal = np.cross(u, v)
    area = np.linalg.norm(normal, axis=1)
    normal = normal / np.maximum(area, 1e-18)[:, None]
    w = point - a
    # The point's foot on each face's plane, in the face's own coordinates.
    uu, vv, uv = (u * u).sum(1), (v * v).sum(1), (u * v).sum(1)
    wu, wv = (w * u).sum(1), (w * v).sum(1)
    det = np.where(area > 0, uu * vv - uv * uv, 1.0)
    s, t = (vv * wu - uv * wv) / det, (uu * wv - uv * wu) / det
    inside = (area > 0) & (s >= -1e-6) & (t >= -1e-6) & (s + t <= 1 + 1e-6)
    plane = np.abs((w * normal).sum(1))
    # Off every face (a click snapped to the outline): the face with the nearest corner.
    corner = np.linalg.norm(tri - point, axis=2).min(axis=1)
    return normal[int(np.argmin(np.where(inside, plane, np.inf)))] if inside.any() \
        else normal[int(np.argmin(corner))]


def facing(camera: CameraModel, point: np.ndarray, world: np.ndarray, shown: np.ndarray,
           scene: SolvedObjects, target: int) -> float | None:
    """Median cosine between the surface normal of object ``target`` at its object-frame
    ``point`` (3,) and the direction from the point to the camera, over the frames where the
    point shows; 1 = faced square on, 0 = seen edge-on. world: (F, 3) the point's track, world
    metres; shown: (F,) bool. None where it never shows."""
    frames = np.flatnonzero(np.asarray(shown, bool) & np.isfinite(world).all(axis=1)
                            & np.isfinite(scene.poses[target]).all(axis=(1, 2)))
    if not frames.size:
        return None
    normal = surface_normal(point, scene.vertices[target], scene.faces[target])
    turned = np.einsum("fij,j->fi", scene.poses[target, frames, :, :3], normal)
    to_camera = camera.T_cam_to_world[:, 3] - world[frames]
    to_camera /= np.linalg.norm(to_camera, axis=1, keepdims=True)
    # Either winding: the side the camera sees is the side that counts.
    return num(np.median(np.abs(np.einsum("fi,fi->f", turned, to_camera))))


def shown_fraction(shown: np.ndarray, known: np.ndarray, anchored: np.ndarray) -> float | None:
    """Least share, over the anchored landmarks, of the frames with a known pose in which the
    landmark's point shows. shown: (F, P) bool; known: (F,) bool; anchored: (P,) bool."""
    if not known.any() or not anchored.any():
        return None
    shares = shown[known][:, anchored].mean(axis=0)
    return num(shares.min())
