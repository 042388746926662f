"""Which camera views pin a target's 3D best: wide baselines first, then cover the weak frames.

Conventions as worker.geometry.cameras: world frame in metres, camera-to-world extrinsics,
image pixels. A view's *ray* to a world point is the unit vector from the point to the camera
centre. Two views pin the point's depth by the sine of the angle between their rays (the
baseline seen from the point): 90 degrees is best, while rays 0 or 180 degrees apart lie on one
line and pin nothing. A view helps only where the point lies in front of the camera and inside
its image.

``initial_views`` picks the first views of a target greedily: the pair of views in which the
target is seen whose rays are closest to right angles (or a given start view), then, one at a
time, the view whose smallest sine to a chosen ray is largest. ``next_view`` picks one more view
for the frames the solve could not trust: the view seeing most of those frames' points, weighted
by the sine it keeps to the nearest view already published there.

A hand's first view is worked from nothing: the hand model is fitted to the worker's first keys
and followed through that view's depth (worker.solver.follow). ``hand_in_view`` reads from a
view's depth alone (a few frames of the clip) whether the moving hand stays whole inside the
image and how far away it is; ``start_views`` names the views to work before any other view's
work can suggest anything: the hand whole on the first frame and on (nearly) every frame after,
the farthest first. A hand cut by the image's edge on the keyed frame gives the fit too few
joints to start from, and one near the camera turns the model's millimetres into more pixels to
correct. In the follow's benchmark (two synthetic 8-view captures, one careful crowd) the
views these rules keep cost 31-76 corrections (mean 48), the others 69-199 (mean 116); a kept
view can still start wrong where the worker's click noise pulls the fit into another pose
(BENCHMARKS.md, "The views worked first").
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass

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


def initial_views(cameras: Sequence[CameraModel], point: np.ndarray, count: int,
                  first: int | None = None, preferred: Collection[int] = ()) -> list[int]:
    """The ``count`` views (indices into ``cameras``) that pin the world ``point`` (3,) best:
    the pair of rays closest to right angles among the views that see it (or the view
    ``first``, whatever it sees), then greedily the view whose smallest sine to a chosen ray
    is largest. The ``preferred`` views that see the point are taken before the other views
    that do, and views that do not see it come last (a target outside every image still gets
    ``count`` views). Ties go to the lower index. ``first`` leads the list."""
    views = len(cameras)
    if count < 1:
        raise ValueError(f"count must be at least 1, got {count}")
    if first is not None and not 0 <= first < views:
        raise ValueError(f"first view {first} is not one of the {views} views")
    if views <= count:
        order = list(range(views))
        return order if first is None else [first] + [v for v in order if v != first]
    r = rays(cameras, np.asarray(point, np.float64).reshape(1, 3))[:, 0]
    visible = seen(cameras, np.asarray(point, np.float64).reshape(1, 3))[:, 0]
    pool = [v for v in range(views) if visible[v]]
    tiers = [[v for v in pool if v in preferred], pool, list(range(views))]
    sines = _sine(r[:, None, :], r[None, :, :])
    chosen: list[int] = [] if first is None else [first]
    if not chosen and count >= 2 and len(pool) != 1:
        pair = next(tier for tier in tiers if len(tier) >= 2)
        sub = sines[np.ix_(pair, pair)]
        i, j = np.unravel_index(int(np.argmax(sub)), sub.shape)
        chosen = sorted((pair[int(i)], pair[int(j)]))
    elif not chosen:
        chosen = [(tiers[0] or tiers[1] or tiers[2])[0]]
    while len(chosen) < count:
        rest = next(left for tier in tiers if (left := [v for v in tier if v not in chosen]))
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


# A reading belongs to what moves (the hand, what it holds) where it lies MOVING_MM or more in
# front of the scene behind it: the BACKGROUND_PERCENTILE of that pixel's readings over the
# sampled frames (the hand passes, the table stays). The moving region is cut by the image's
# edge where more than EDGE_READINGS of its readings lie within EDGE_PX of it (a few stray
# readings are sensor noise), and too small to follow under MIN_MOVING_READINGS (about a
# 60 x 17 px hand: a palm a metre and a half away, or a hand mostly behind the object).
MOVING_MM = 20.0
BACKGROUND_PERCENTILE = 90.0
EDGE_PX = 4
EDGE_READINGS = 20
MIN_MOVING_READINGS = 1000
# A start view keeps the hand whole on at least this share of the sampled frames after the
# first (the follow is carried through them; where the hand leaves the image it stops and the
# worker keys the rest by hand).
START_WHOLE_SHARE = 0.9


@dataclass(frozen=True)
class HandInView:
    """What a view's depth says of the moving hand: whether its region is whole (inside the
    image, big enough) on the first sampled frame, on what share of the sampled frames, and
    its median distance from the camera (mm, NaN when nothing moves)."""

    whole_first: bool
    whole_share: float
    depth_mm: float


def hand_in_view(depth: np.ndarray) -> HandInView:
    """:class:`HandInView` of one view from depth (S, H, W) mm (0 = no reading) of S >= 2
    frames sampled through the clip, the first of them the clip's first frame."""
    depth = np.asarray(depth)
    if depth.ndim != 3 or depth.shape[0] < 2:
        raise ValueError(f"expected depth (S >= 2, H, W), got {depth.shape}")
    # The scene behind: each pixel's BACKGROUND_PERCENTILE reading (a missing one, 0, counted
    # as the nearest), by one partition of the samples rather than a NaN-aware percentile.
    rank = round(BACKGROUND_PERCENTILE / 100.0 * (len(depth) - 1))
    behind = np.partition(depth, rank, axis=0)[rank].astype(np.float64)
    mm = depth.astype(np.float64)
    moving = (mm > 0) & (mm < behind[None] - MOVING_MM)
    edge = np.zeros(depth.shape[1:], bool)
    edge[:EDGE_PX], edge[-EDGE_PX:], edge[:, :EDGE_PX], edge[:, -EDGE_PX:] = True, True, True, True
    counts = moving.reshape(len(mm), -1).sum(axis=1)
    cut = (moving & edge[None]).reshape(len(mm), -1).sum(axis=1) > EDGE_READINGS
    whole = (counts >= MIN_MOVING_READINGS) & ~cut
    far = float(np.median(mm[moving])) if moving.any() else float("nan")
    return HandInView(bool(whole[0]), float(whole[1:].mean()), far)


def start_views(found: Sequence[HandInView | None]) -> list[int]:
    """The views (indices into ``found``; None where a view has no depth) whose hand is whole
    on the first frame and on START_WHOLE_SHARE of the rest, farthest first (ties: the lower
    index): a hand's first view is the first of them; empty when none qualifies."""
    fit = [(v, h.depth_mm) for v, h in enumerate(found)
           if h is not None and h.whole_first and h.whole_share >= START_WHOLE_SHARE
           and np.isfinite(h.depth_mm)]
    return [v for v, _ in sorted(fit, key=lambda item: (-item[1], item[0]))]
