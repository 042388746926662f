"""Z-buffered triangle rasterisation in NumPy for an ideal pinhole camera.

Pixel centres sit at integer coordinates (OpenCV convention), so pixel (x, y) is covered by a
triangle when the point (x, y) lies inside its projection. Every triangle is expanded into the
candidate pixels of its bounding box, in batches of triangles with similar box sizes; the nearest
candidate per pixel wins through one ``np.minimum.at`` on a key that packs quantised depth above
the triangle id. Barycentric coordinates of the winners are then recomputed exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NEAR_PLANE = 0.05  # metres; triangles with a vertex closer than this are dropped, not clipped
_DEPTH_QUANTUM = 1e-7  # metres per unit of the packed z-buffer key
_ID_BITS = 24  # up to 16.7 M triangles per image
# Pixels exactly on an edge shared by two triangles must not fall through both by rounding.
_EDGE_EPS = 1e-9
_CHUNK = 1_000_000  # candidate pixels per vectorised batch, bounds the memory used


@dataclass(frozen=True)
class Fragments:
    """Per-pixel result of rasterisation (H = height, W = width, P = drawn pixels).

    Attributes:
        tri: (H, W) int64 winning triangle index, -1 where nothing is drawn.
        depth: (H, W) float64 camera z of the surface in metres, 0 where nothing is drawn.
        pixels: (P,) int64 flat indices (y * W + x) of the drawn pixels, ascending.
        bary: (P, 3) float32 perspective-correct barycentric weights of the winners' corners.
    """

    tri: np.ndarray
    depth: np.ndarray
    pixels: np.ndarray
    bary: np.ndarray


def _plane_coefficients(uv: np.ndarray, inv_z: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 4, 3) affine screen-space functions a x + b y + c per triangle: the three
    barycentric weights and 1/z (1/z of a planar triangle is affine in screen space)."""
    a, b, c = (uv[faces[:, k]] for k in range(3))
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    coef = np.empty((len(faces), 4, 3))
    for k, (p, q) in enumerate(((b, c), (c, a), (a, b))):
        # Weight of corner k: signed area of (p, q, x) over the triangle's area.
        coef[:, k, 0] = (p[:, 1] - q[:, 1]) / area
        coef[:, k, 1] = (q[:, 0] - p[:, 0]) / area
        coef[:, k, 2] = (p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]) / area
    coef[:, 3] = np.einsum("fk,fkc->fc", inv_z[faces], coef[:, :3])
    return coef


# Integer pixel boxes (x0, y0, x1, y1) of triangles, each (F,) int64.
_Boxes = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _candidates(ids: np.ndarray, box: _Boxes, grid_w: int, grid_h: int, coef: np.ndarray,
                width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Candidate pixels inside triangles ``ids`` whose boxes fit a (grid_h, grid_w) grid.

    Returns flat pixel indices, 1/z (1/metres) and triangle ids of the covered pixels.
    """
    x0, y0, x1, y1 = (b[ids, None, None] for b in box)
    oy, ox = np.mgrid[0:grid_h, 0:grid_w]
    c = coef[ids][:, :, :, None, None]  # (n, 4, 3, 1, 1)
    base = c[:, :, 0] * x0[:, None] + c[:, :, 1] * y0[:, None] + c[:, :, 2]  # (n, 4, 1, 1)
    values = base + c[:, :, 0] * ox + c[:, :, 1] * oy  # (n, 4, gh, gw)
    inside = (values[:, 0] >= -_EDGE_EPS) & (values[:, 1] >= -_EDGE_EPS) & (
        values[:, 2] >= -_EDGE_EPS)
    inside &= (ox <= x1 - x0) & (oy <= y1 - y0)
    pix = (y0 * width + x0) + (oy * width + ox)
    tri = np.broadcast_to(ids[:, None, None], inside.shape)
    return pix[inside], values[:, 3][inside], tri[inside]


def _quantised(size: np.ndarray) -> np.ndarray:
    """Round box sides up to a grid of two steps per octave (at most 50 % padding)."""
    step = np.maximum(1, 2 ** np.maximum(np.floor(np.log2(np.maximum(size, 1))) - 1, 0))
    return (np.ceil(size / step) * step).astype(np.int64)


def _batches(ids: np.ndarray, box: _Boxes) -> list[tuple[np.ndarray, int, int]]:
    """Split triangles into (ids, grid_w, grid_h) batches of similar bounding-box size."""
    x0, y0, x1, y1 = box
    qw, qh = _quantised(x1[ids] - x0[ids] + 1), _quantised(y1[ids] - y0[ids] + 1)
    shapes, inverse = np.unique(np.stack([qw, qh], axis=1), axis=0, return_inverse=True)
    out: list[tuple[np.ndarray, int, int]] = []
    for k, (gw, gh) in enumerate(shapes):
        group = ids[inverse.reshape(-1) == k]
        per = max(1, _CHUNK // int(gw * gh))
        out += [(group[i:i + per], int(gw), int(gh)) for i in range(0, len(group), per)]
    return out


def _boxes(uv: np.ndarray, faces: np.ndarray, width: int, height: int) -> _Boxes:
    """Integer pixel boxes (x0, y0, x1, y1) of projected triangles, clipped to the image."""
    tri_uv = uv[faces]
    lo = np.ceil(tri_uv.min(axis=1)).astype(np.int64)
    hi = np.floor(tri_uv.max(axis=1)).astype(np.int64)
    x0, y0 = np.maximum(lo[:, 0], 0), np.maximum(lo[:, 1], 0)
    x1, y1 = np.minimum(hi[:, 0], width - 1), np.minimum(hi[:, 1], height - 1)
    return x0, y0, x1, y1


def rasterize(
    points_cam: np.ndarray, faces: np.ndarray, K: np.ndarray, width: int, height: int
) -> Fragments:
    """Rasterise triangles seen by a pinhole camera (no distortion: worker.synth.render and
    worker.overlay handle a lens).

    Args:
        points_cam: (N, 3) vertices in the camera frame (OpenCV: z forward), metres.
        faces: (F, 3) int vertex indices; both windings are drawn (no back-face culling).
        K: (3, 3) intrinsics, pixels.
        width, height: image size, pixels.

    Returns:
        :class:`Fragments` for the (height, width) image.
    """
    points_cam = np.asarray(points_cam, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if points_cam.ndim != 2 or points_cam.shape[1] != 3:
        raise ValueError(f"points_cam must have shape (N, 3), got {points_cam.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {faces.shape}")
    z = points_cam[:, 2]
    safe_z = np.where(z > NEAR_PLANE, z, 1.0)
    uv = np.empty((len(points_cam), 2))
    uv[:, 0] = K[0, 0] * points_cam[:, 0] / safe_z + K[0, 1] * points_cam[:, 1] / safe_z + K[0, 2]
    uv[:, 1] = K[1, 1] * points_cam[:, 1] / safe_z + K[1, 2]
    inv_z = 1.0 / safe_z
    x0, y0, x1, y1 = _boxes(uv, faces, width, height)
    keep = (z[faces] > NEAR_PLANE).all(axis=1) & (x1 >= x0) & (y1 >= y0)
    e1, e2 = uv[faces[:, 1]] - uv[faces[:, 0]], uv[faces[:, 2]] - uv[faces[:, 0]]
    area = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    keep &= np.abs(area) > 1e-12
    ids = np.flatnonzero(keep)
    coef = np.zeros((len(faces), 4, 3))
    coef[ids] = _plane_coefficients(uv, inv_z, faces[ids])
    key = np.full(width * height, np.iinfo(np.uint64).max, dtype=np.uint64)
    box = (x0, y0, x1, y1)
    for batch, grid_w, grid_h in _batches(ids, box):
        pix, z_inv, tri = _candidates(batch, box, grid_w, grid_h, coef, width)
        dq = np.minimum(1.0 / (z_inv * _DEPTH_QUANTUM), 2.0 ** (64 - _ID_BITS) - 1)
        np.minimum.at(key, pix, (dq.astype(np.uint64) << np.uint64(_ID_BITS)) | tri.astype(
            np.uint64))
    return _resolve(key, coef, inv_z, faces, width, height)


def _resolve(key: np.ndarray, coef: np.ndarray, inv_z: np.ndarray, faces: np.ndarray,
             width: int, height: int) -> Fragments:
    """Turn the packed z-buffer into triangle ids, perspective-correct weights and depth.

    Depth comes straight from the key (quantised to _DEPTH_QUANTUM); the weights, used only for
    shading, are evaluated in float32.
    """
    pixels = np.flatnonzero(key != np.iinfo(np.uint64).max)
    packed = key[pixels]
    winner = (packed & np.uint64((1 << _ID_BITS) - 1)).astype(np.int64)
    px, py = (pixels % width).astype(np.float32), (pixels // width).astype(np.float32)
    c = coef[:, :2].astype(np.float32)[winner]  # (P, 2, 3): weights of corners 0 and 1
    w = c[:, :, 0] * px[:, None] + c[:, :, 1] * py[:, None] + c[:, :, 2]
    w = np.concatenate([w, 1.0 - w.sum(axis=1, keepdims=True)], axis=1)
    w = np.clip(w, 0.0, None)
    w *= inv_z.astype(np.float32)[faces[winner]]
    w /= w.sum(axis=1, keepdims=True)
    tri = np.full(width * height, -1, dtype=np.int64)
    tri[pixels] = winner
    depth = np.zeros(width * height)
    depth[pixels] = (packed >> np.uint64(_ID_BITS)).astype(np.float64) * _DEPTH_QUANTUM
    return Fragments(tri.reshape(height, width), depth.reshape(height, width), pixels, w)
