"""Which camera views pin a target's 3D best: wide baselines first, then cover the weak frames.

Conventions as worker.geometry.cameras: world frame in metres, camera-to-world extrinsics,
image pixels. A view's *ray* to a world point is the unit vector from the point to the camera
centre. Two views pin the point's depth by the sine of the angle between their rays (the
baseline seen from the point): 90 degrees is best, while rays 0 or 180 degrees apart lie on one
line and pin nothing. A view helps only where the point lies in front of the camera and inside
its image.

``initial_views`` picks the first views of a target greedily: the pair of views in which the
target is seen whose rays are closest to right angles, then, one at a time, the view whose
smallest sine to a chosen ray is largest. ``next_view`` picks one more view for the frames the
solve could not trust: the view seeing most of those frames' points, weighted by the sine it
keeps to the nearest view already published there.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from worker.geometry.cameras import CameraModel, project_points, world_to_camera


def rig_centre(cameras: Sequence[CameraModel]) -> np.ndarray:
    """(3,) world point nearest (least squares) to every camera's optical axis, metres: where
    the rig looks, the target's place when nothing better is known."""
    if len(cameras) < 2:
        raise ValueError(f"a rig centre needs at least 2 cameras, got {len(cameras)}")
    A, b = np.zeros((3, 3)), np.zeros(3)
    for camera in cameras:
        T = np.asarray(camera.T_cam_to_world, np.float64)
        centre, axis = T[:, 3], T[:, 2] / np.linalg.norm(T[:, 2])
        P = np.eye(3) - np.outer(axis, axis)
        A += P
        b += P @ centre
    return np.asarray(np.linalg.lstsq(A, b, rcond=None)[0], np.float64)


def rays(cameras: Sequence[CameraModel], points: np.ndarray) -> np.ndarray:
    """(V, N, 3) unit vectors from each of the (N, 3) world points to each camera centre."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    centres = np.stack([np.asarray(c.T_cam_to_world, np.float64)[:, 3] for c in cameras])
    d = centres[:, None, :] - points[None, :, :]
    return np.asarray(d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12))


def seen(cameras: Sequence[CameraModel], points: np.ndarray) -> np.ndarray:
    """(V, N) bool: the (N, 3) world point lies in front of the camera and inside its image
    (NaN points are seen nowhere)."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    finite = np.isfinite(points).all(axis=1)
    out = np.zeros((len(cameras), len(points)), bool)
    for v, camera in enumerate(cameras):
        if not finite.any():
            break
        depth = world_to_camera(points[finite], camera.T_cam_to_world)[:, 2]
        px = project_points(points[finite], camera.K, camera.T_cam_to_world, camera.dist)
        inside = ((px[:, 0] >= 0) & (px[:, 0] <= camera.width - 1)
                  & (px[:, 1] >= 0) & (px[:, 1] <= camera.height - 1))
        out[v, finite] = (depth > 0) & inside
    return out


def _sine(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Sine of the angle between unit vectors (..., 3): 1 at right angles, 0 on one line."""
    return np.asarray(np.linalg.norm(np.cross(a, b), axis=-1))


def initial_views(cameras: Sequence[CameraModel], point: np.ndarray, count: int) -> list[int]:
    """The ``count`` views (indices into ``cameras``) that pin the world ``point`` (3,) best:
    the pair of rays closest to right angles among the views that see it, then greedily the
    view whose smallest sine to a chosen ray is largest. Views that do not see the point come
    last (a target outside every image still gets ``count`` views). Ties go to the lower
    index."""
    views = len(cameras)
    if count < 1:
        raise ValueError(f"count must be at least 1, got {count}")
    if views <= count:
        return list(range(views))
    r = rays(cameras, np.asarray(point, np.float64).reshape(1, 3))[:, 0]
    visible = seen(cameras, np.asarray(point, np.float64).reshape(1, 3))[:, 0]
    pool = [v for v in range(views) if visible[v]] or list(range(views))
    sines = _sine(r[:, None, :], r[None, :, :])
    chosen: list[int] = []
    if len(pool) >= 2 and count >= 2:
        sub = sines[np.ix_(pool, pool)]
        i, j = np.unravel_index(int(np.argmax(sub)), sub.shape)
        chosen = sorted((pool[int(i)], pool[int(j)]))
    elif pool:
        chosen = [pool[0]]
    while len(chosen) < count:
        rest = [v for v in pool if v not in chosen]
        if not rest:
            pool = list(range(views))
            rest = [v for v in pool if v not in chosen]
        spread = [float(sines[v, chosen].min()) if chosen else 0.0 for v in rest]
        chosen.append(rest[int(np.argmax(spread))])
    return chosen


def next_view(cameras: Sequence[CameraModel], published: Sequence[int],
              candidates: Sequence[int], points: np.ndarray) -> tuple[int, float]:
    """The candidate view that best covers the weak frames' world ``points`` (F, N, 3) (NaN
    where unknown), and its score in [0, 1]: the mean over the finite points of "seen by the
    view" times the smallest sine between its ray and a published view's ray there. Ties go
    to the earliest candidate."""
    if not candidates:
        raise ValueError("no candidate view to choose from")
    flat = np.asarray(points, np.float64).reshape(-1, 3)
    flat = flat[np.isfinite(flat).all(axis=1)]
    if not len(flat):
        raise ValueError("no finite point to cover")
    r = rays(cameras, flat)
    visible = seen(cameras, flat)
    scores = []
    for v in candidates:
        gain = (np.min(np.stack([_sine(r[v], r[p]) for p in published]), axis=0)
                if published else np.ones(len(flat)))
        scores.append(float((visible[v] * gain).mean()))
    best = int(np.argmax(scores))
    return int(candidates[best]), scores[best]
