"""The geometric symmetries of an object mesh, as BOP's models_info.json lists them.

Pure: a mesh in, ``symmetries_continuous`` and ``symmetries_discrete`` out (bop_toolkit's
``docs/bop_datasets_format.md``): a continuous symmetry is {"axis": unit [x, y, z], "offset":
a point [x, y, z] on the axis in mm}; a discrete one is a 4x4 rigid transform in the model
frame, 16 numbers row-major with the translation in mm.

Found by testing candidates against the surface: the mesh is sampled uniformly over its area
(fixed seed), candidate rotations are taken about the principal axes of the samples through
their centroid, and a candidate is a symmetry when the 99th percentile of the transformed
samples' distance to the nearest original sample exceeds the sampling's own (a second sample
set against the first) by at most :data:`TOLERANCE_OF_DIAMETER` of the diameter.

Continuous: an axis about which turns of 360/7 deg, 2 x 360/7 deg and 3 x 360/7 deg (angles
no polygonal prism maps onto itself unless it is a 7-gon) all pass. Discrete: turns of
360 k / n deg (n = 2, 3, 4, 6) about each principal axis that is not a continuous axis, and,
for a continuous axis, the half turns about the other two (a cylinder turned end over end).
Only the geometry is considered (texture is not): the symmetries BOP's geometric pose errors
(MSSD, MSPD) need. An asymmetric mesh gets empty lists.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

MM_PER_M = 1000.0
SAMPLES = 6000
TOLERANCE_OF_DIAMETER = 0.01
_SEED = 7
_CONTINUOUS_TURNS = (2 * np.pi / 7, 4 * np.pi / 7, 6 * np.pi / 7)
_DISCRETE_ORDERS = (2, 3, 4, 6)


def surface_samples(vertices: np.ndarray, faces: np.ndarray, count: int, seed: int
                    ) -> np.ndarray:
    """``count`` points (count, 3) spread uniformly over the mesh's area, same units as the
    vertices (N, 3); faces (M, 3) int."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if not len(tri) or area.sum() <= 0:
        raise ValueError("the mesh has no area to sample")
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(tri), size=count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[pick]
    out: np.ndarray = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    return out


def surface_moments(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The surface's exact area-weighted centroid (3,) and mean of x x^T (3, 3) over its area.

    Over a triangle (a, b, c) of area A the integral of x x^T is A / 12 (a a^T + b b^T + c c^T
    + s s^T) with s = a + b + c; exact moments keep the axes of a symmetric mesh exact.
    """
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    total = float(area.sum())
    if total <= 0:
        raise ValueError("the mesh has no area")
    s = tri.sum(axis=1)
    centre = (area[:, None] * s / 3).sum(axis=0) / total
    outer = np.einsum("tvi,tvj->tij", tri, tri) + np.einsum("ti,tj->tij", s, s)
    second = (area[:, None, None] * outer).sum(axis=0) / (12 * total)
    return centre, second


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues: the (3, 3) rotation by ``angle`` rad about the unit ``axis``."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


class _Surface:
    """The sampled surface and the test of one rotation about a line through ``centre``."""

    def __init__(self, vertices_mm: np.ndarray, faces: np.ndarray) -> None:
        self.points = surface_samples(vertices_mm, faces, SAMPLES, _SEED)
        self.tree = cKDTree(self.points)
        self.centre, second = surface_moments(vertices_mm, faces)
        _, vectors = np.linalg.eigh(second - np.outer(self.centre, self.centre))
        self.axes = [vectors[:, i] / np.linalg.norm(vectors[:, i]) for i in range(3)]
        other = surface_samples(vertices_mm, faces, SAMPLES, _SEED + 1)
        noise = float(np.percentile(self.tree.query(other)[0], 99))
        extent = np.ptp(self.points, axis=0)
        self.limit = noise + TOLERANCE_OF_DIAMETER * float(np.linalg.norm(extent))

    def maps_onto_itself(self, rotation: np.ndarray) -> bool:
        moved = (self.points - self.centre) @ rotation.T + self.centre
        return float(np.percentile(self.tree.query(moved)[0], 99)) <= self.limit

    def transform(self, rotation: np.ndarray) -> list[float]:
        """The 4x4 row-major transform of a rotation about the centre, translation in mm."""
        matrix = np.eye(4)
        matrix[:3, :3] = rotation
        matrix[:3, 3] = self.centre - rotation @ self.centre
        return [round(float(v), 6) + 0.0 for v in matrix.ravel()]


def bop_symmetries(vertices: np.ndarray, faces: np.ndarray) -> dict[str, Any]:
    """models_info.json's symmetry fields of a mesh: vertices (N, 3) metres, faces (M, 3).

    Returns {"symmetries_continuous": [...]} and/or {"symmetries_discrete": [...]}, each only
    when not empty (BOP leaves the keys out for an asymmetric object).
    """
    surface = _Surface(np.asarray(vertices, dtype=np.float64) * MM_PER_M, faces)
    continuous = [axis for axis in surface.axes
                  if all(surface.maps_onto_itself(_rotation(axis, a)) for a in _CONTINUOUS_TURNS)]
    discrete: list[list[float]] = []
    seen: list[np.ndarray] = []
    for axis in surface.axes:
        on_continuous = any(abs(float(axis @ c)) > 0.999 for c in continuous)
        orders: tuple[int, ...] = () if on_continuous else _DISCRETE_ORDERS
        if continuous and not on_continuous:
            orders = (2,)
        for n in orders:
            for k in range(1, n):
                rotation = _rotation(axis, 2 * np.pi * k / n)
                if any(np.allclose(rotation, r, atol=1e-6) for r in seen):
                    continue
                if surface.maps_onto_itself(rotation):
                    seen.append(rotation)
                    discrete.append(surface.transform(rotation))
    out: dict[str, Any] = {}
    if continuous:
        out["symmetries_continuous"] = [
            {"axis": [round(float(v), 6) + 0.0 for v in axis],
             "offset": [round(float(v), 6) + 0.0 for v in surface.centre]} for axis in continuous]
    if discrete:
        out["symmetries_discrete"] = discrete
    return out
