"""The depth camera's verdict on whether points are visible in one view: one rule for the
visibility pre-fill suggests (worker.assist.prefill) and for QC's check of the workers'
visibility flags (worker.quality.metrics.depth_visibility, worker.quality.consensus).

Conventions as in worker.geometry.cameras: pixels x right, y down; world metres; depth maps
(F, H, W) uint16 millimetres along the camera's z axis, 0 = no reading. F frames, P points.
Pure: arrays in, arrays out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.hand.joints import JOINT_PARENTS

# Depth margins (metres) for the visibility check, from the synthetic capture (seed 7, 8 views,
# 72 frames): a visible joint lies under the skin, so the depth camera sees the surface a little
# nearer (z - depth: median 12.5 mm, 75th percentile 22 mm, sensor noise ~1 mm at 0.7 m); an
# object-covered joint reads 5-11 cm nearer (10th percentile 51 mm). Between the margins the
# verdict is left open (hand self-occlusion by a finger or the palm falls there or above).
SURFACE_MARGIN_M = 0.025
HIDDEN_MARGIN_M = 0.05
# A hand covers its own joints (a finger curled in front of another, the back of the hand in
# front of the palm side): the reading then lies on the hand itself, and whether a worker marks
# such a joint occluded is left open (the synthetic ground truth calls it visible, the page's
# instructions occluded); only something other than the hand makes it hidden. Synthetic
# capture seed 7, 8 views: such readings lie 7-18 mm from the hand's skeleton (bones and palm;
# 99th percentile), up to 23 mm at the palm's edge; an object's surface in front of a joint
# 15-64 mm (median 29 mm). Nearer than this the reading is taken for the hand's
# own surface and judges nothing. At the true joints of seeds 5 (320x240), 7 and 23: 0.4-7 % of
# the joints judged hidden are visible in truth (at an object's outline), against 33-71 % with
# the hand's own surface counted; 66-78 % of the truly occluded joints are judged hidden
# (70-88 % counting the hand's own surface too).
OWN_SURFACE_M = 0.02
# The hand's skeleton in DexYCB joint order (worker.hand.joints): each bone, the knuckle line and
# the thumb's base to the index knuckle; the palm as the triangles between them.
_HAND_JOINTS = 21
_HAND_SEGMENTS = np.array([(j, p) for j, p in enumerate(JOINT_PARENTS) if p >= 0]
                          + [(1, 5), (5, 9), (9, 13), (13, 17)])
_PALM = np.array([(0, 1, 5), (0, 5, 9), (0, 9, 13), (0, 13, 17)])
# Half-width (px) of the square around a point searched for a reading that sees as far as the
# point (as the ground truth of the synthetic annotators looks 2 px around a joint).
WINDOW_RADIUS_PX = 2

class DepthMaps(Protocol):
    """One view's (F, H, W) uint16 depth maps as the visibility check reads them: an ndarray,
    or anything with its ``shape`` and (frames, rows, cols) integer-array indexing (a stack
    read lazily, for one)."""

    @property
    def shape(self) -> tuple[int, ...]: ...

    def __getitem__(self, index: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray: ...


@dataclass(frozen=True)
class SurfaceCheck:
    """What one view's depth map says of the reference points, (F, P) bool each: on_surface
    (the reading at the point's pixel is at most the surface margin nearer than the point:
    nothing covers it) and hidden (that reading and every other within WINDOW_RADIUS_PX more
    than the hidden margin nearer, and for a hand not its own surface: something else covers
    it). Points in between, covered by the hand itself, off-image or without a reading at
    their pixel are neither."""

    on_surface: np.ndarray
    hidden: np.ndarray


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(F, N, S) distance from points (F, N, 3) to segments a-b (F, S, 3), metres."""
    ab = (b - a)[:, None]
    ap = points[:, :, None] - a[:, None]
    t = np.clip(np.sum(ap * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-12), 0, 1)
    return np.linalg.norm(ap - t[..., None] * ab, axis=-1)


def _plane_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray,
                    c: np.ndarray) -> np.ndarray:
    """(F, N, T) distance from points (F, N, 3) to triangles abc (F, T, 3) where the point's
    foot on the triangle's plane falls inside it; infinity elsewhere (an edge is nearer)."""
    u, v = (b - a)[:, None], (c - a)[:, None]
    w = points[:, :, None] - a[:, None]
    uu, vv, uv = np.sum(u * u, -1), np.sum(v * v, -1), np.sum(u * v, -1)
    wu, wv = np.sum(w * u, -1), np.sum(w * v, -1)
    det = uu * vv - uv * uv
    ok = det > 1e-18
    det = np.where(ok, det, 1.0)
    s, t = (vv * wu - uv * wv) / det, (uu * wv - uv * wu) / det
    inside = ok & (s >= 0) & (t >= 0) & (s + t <= 1)
    foot = s[..., None] * u + t[..., None] * v
    return np.where(inside, np.linalg.norm(w - foot, axis=-1), np.inf)


def distance_to_hand(points: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(F, N) distance (metres) from points (F, N, 3) to the hand's skeleton given by its 21
    joints (F, 21, 3) in the same frame: the nearest bone, knuckle line or palm triangle.
    Parts with a missing (NaN) joint are left out; infinity where none is left."""
    if joints.ndim != 3 or joints.shape[1:] != (_HAND_JOINTS, 3) or points.ndim != 3 \
            or points.shape[0] != joints.shape[0] or points.shape[2] != 3:
        raise ValueError(f"expected points (F, N, 3) and joints (F={points.shape[0]}, 21, 3), "
                         f"got {points.shape} and {joints.shape}")
    seg = _segment_distance(points, joints[:, _HAND_SEGMENTS[:, 0]],
                            joints[:, _HAND_SEGMENTS[:, 1]])
    palm = _plane_distance(points, *(joints[:, _PALM[:, k]] for k in range(3)))
    both = np.concatenate([seg, palm], axis=-1)
    return np.where(np.isnan(both), np.inf, both).min(axis=-1)


def surface_check(camera: CameraModel, points_world: np.ndarray, depth_mm: DepthMaps,
                  surface_margin_m: float = SURFACE_MARGIN_M,
                  hidden_margin_m: float = HIDDEN_MARGIN_M,
                  own_surface_m: float = OWN_SURFACE_M) -> SurfaceCheck:
    """Look the reference points up in the view's depth map (once per view: every label of the
    view is judged against the same points).

    Args:
        camera: the view. points_world: (F, P, 3) reference points, world metres (NaN: none);
            with P = 21 they are a hand's joints, and a nearer reading on that hand itself
            (within own_surface_m of its skeleton) hides nothing.
        depth_mm: (F, H, W) uint16 depth along the camera's z axis, millimetres, 0 = no
            reading (any array-like that supports ``shape`` and (frames, rows, cols) indexing).
        surface_margin_m, hidden_margin_m, own_surface_m: see SurfaceCheck, OWN_SURFACE_M.
    """
    frames, height, width = depth_mm.shape
    if depth_mm.shape[0] != points_world.shape[0]:
        raise ValueError(f"depth_mm must have shape (F={points_world.shape[0]}, H, W), "
                         f"got {depth_mm.shape}")
    pix = camera.project(points_world)
    z = camera.depth_of(points_world)
    col, row = np.rint(pix[..., 0]), np.rint(pix[..., 1])
    inside = np.isfinite(z) & (z > 0) & (col >= 0) & (col < width) & (row >= 0) & (row < height)
    # One lookup of the window around each point: its centre, and every pixel of it.
    r = WINDOW_RADIUS_PX
    offsets = np.array([(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)])
    f_idx = np.broadcast_to(np.arange(frames)[:, None], z.shape)[inside]
    rows = np.clip(row[inside].astype(int)[:, None] + offsets[:, 0], 0, height - 1)
    cols = np.clip(col[inside].astype(int)[:, None] + offsets[:, 1], 0, width - 1)
    window = np.asarray(depth_mm[np.broadcast_to(f_idx[:, None], rows.shape), rows, cols],
                        dtype=np.float64) / 1000.0
    reading, farthest = np.zeros(z.shape), np.zeros(z.shape)
    reading[inside] = window[:, len(offsets) // 2]
    farthest[inside] = window.max(axis=1)
    judged = inside & (reading > 0)
    on_surface = judged & (z - reading <= surface_margin_m)
    # Hidden only where no pixel of the window sees as far as the point: a reference point a
    # pixel or two off (the consensus, or a joint at an outline) lands on whatever lies beside.
    # Its own pixel must read too: a dropout there marks a depth edge, where nothing is sure.
    hidden = judged & (z - farthest > hidden_margin_m)
    if points_world.shape[1] == _HAND_JOINTS and hidden.any():
        # The surface the camera sees along the point's ray, at the reading's depth.
        centre = camera.T_cam_to_world[:, 3]
        scale = np.where(hidden, farthest / np.where(hidden, z, 1.0), np.nan)
        surface = centre + (points_world - centre) * scale[..., None]
        hidden &= ~(distance_to_hand(surface, points_world) < own_surface_m)
    return SurfaceCheck(on_surface=on_surface, hidden=hidden)
