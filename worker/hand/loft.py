"""Closed tube meshes lofted along a centre line, with rounded end caps.

A loft is a sequence of cross-section rings (superellipses in each ring's plane) joined by
triangle strips, closed at each end by extra rings that shrink towards a pole vertex. Every loft
is a closed, consistently oriented surface whose triangles wind counter-clockwise seen from
outside. Lengths are metres in whatever frame the centres are given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Loft:
    """A closed tube mesh.

    vertices: (V, 3) metres. faces: (F, 3) int64, outward winding.
    arc: (V,) each vertex's position along the centre line, metres (caps extend past the ends).
    centres: (V, 3) the centre of each vertex's ring (the pole itself for poles).
    ring_starts: (R,) index of the first vertex of each main (non-cap) ring; rings are contiguous.
    ring_size: vertices per ring. tip: index of the pole past the last ring.
    """

    vertices: np.ndarray
    faces: np.ndarray
    arc: np.ndarray
    centres: np.ndarray
    ring_starts: np.ndarray
    ring_size: int
    tip: int


def _signed_power(x: np.ndarray, p: float) -> np.ndarray:
    return np.sign(x) * np.abs(x) ** p


def ring_points(
    centres: np.ndarray,
    lateral: np.ndarray,
    palmar: np.ndarray,
    half_axes: np.ndarray,
    ring_size: int,
    exponent: float,
) -> np.ndarray:
    """Superellipse rings |u/a|^e + |w/b|^e = 1 around each centre.

    centres, lateral, palmar: (R, 3); lateral and palmar are unit vectors spanning each ring's
    plane. half_axes: (R, 2) half-axes (a along lateral, b along palmar), metres. ring_size must be
    even, so opposite points pair up and each ring's vertex mean is exactly its centre.
    Returns (R, ring_size, 3).
    """
    if ring_size % 2:
        raise ValueError(f"ring_size must be even, got {ring_size}")
    angle = 2.0 * np.pi * np.arange(ring_size) / ring_size
    cos = _signed_power(np.cos(angle), 2.0 / exponent)
    sin = _signed_power(np.sin(angle), 2.0 / exponent)
    along_lateral = half_axes[:, 0, None, None] * cos[None, :, None] * lateral[:, None, :]
    along_palmar = half_axes[:, 1, None, None] * sin[None, :, None] * palmar[:, None, :]
    return centres[:, None, :] + along_lateral + along_palmar


def _cap_rings(count: int) -> tuple[np.ndarray, np.ndarray]:
    """Axial fraction (sin) and radial scale (cos) of `count` cap rings, innermost first."""
    alpha = np.arange(1, count + 1) / (count + 1) * (np.pi / 2.0)
    return np.sin(alpha), np.cos(alpha)


def _strip_faces(n_rings: int, ring_size: int, first: int) -> np.ndarray:
    """Triangles joining consecutive rings that start at vertex `first`."""
    k, i = np.meshgrid(np.arange(n_rings - 1), np.arange(ring_size), indexing="ij")
    a = first + k * ring_size + i
    b = first + k * ring_size + (i + 1) % ring_size
    c, d = b + ring_size, a + ring_size
    quads = np.stack((a, b, c, d), axis=-1).reshape(-1, 4)
    return np.concatenate((quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]))


def _fan_faces(pole: int, ring_first: int, ring_size: int, at_start: bool) -> np.ndarray:
    i = np.arange(ring_size)
    a, b = ring_first + i, ring_first + (i + 1) % ring_size
    pole_col = np.full(ring_size, pole)
    return np.stack((b, a, pole_col) if at_start else (a, b, pole_col), axis=1)


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by a closed triangle mesh, m^3; positive when faces wind outward."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _with_caps(
    centres: np.ndarray,
    lateral: np.ndarray,
    palmar: np.ndarray,
    half_axes: np.ndarray,
    arc: np.ndarray,
    caps: tuple[tuple[float, int], tuple[float, int]],
) -> tuple:
    """Prepend/append shrinking cap rings (see `loft`): the extended ring arrays (centres,
    lateral, palmar, half_axes, arc), the two pole positions and the poles' arc positions."""
    tangent_start = centres[1] - centres[0]
    tangent_end = centres[-1] - centres[-2]
    tangent_start, tangent_end = (t / np.linalg.norm(t) for t in (tangent_start, tangent_end))
    (len0, n0), (len1, n1) = caps
    ax0, sc0 = _cap_rings(n0)
    ax1, sc1 = _cap_rings(n1)
    ax0, sc0 = ax0[::-1], sc0[::-1]  # outermost (closest to the pole) first
    c = np.concatenate((centres[0] - len0 * ax0[:, None] * tangent_start, centres,
                        centres[-1] + len1 * ax1[:, None] * tangent_end))
    h = np.concatenate((half_axes[0] * sc0[:, None], half_axes, half_axes[-1] * sc1[:, None]))
    lat = np.concatenate((np.repeat(lateral[:1], n0, 0), lateral, np.repeat(lateral[-1:], n1, 0)))
    pal = np.concatenate((np.repeat(palmar[:1], n0, 0), palmar, np.repeat(palmar[-1:], n1, 0)))
    s = np.concatenate((arc[0] - len0 * ax0, arc, arc[-1] + len1 * ax1))
    poles = (centres[0] - len0 * tangent_start, centres[-1] + len1 * tangent_end)
    return c, lat, pal, h, s, poles, (arc[0] - len0, arc[-1] + len1)


def loft(
    centres: np.ndarray,
    lateral: np.ndarray,
    palmar: np.ndarray,
    half_axes: np.ndarray,
    arc: np.ndarray,
    *,
    ring_size: int,
    exponent: float = 2.0,
    caps: tuple[tuple[float, int], tuple[float, int]],
) -> Loft:
    """Loft a closed tube through R >= 2 main rings.

    centres, lateral, palmar: (R, 3) ring centres and in-plane unit axes; half_axes: (R, 2);
    arc: (R,) centre-line position of each ring, metres. caps: ((length, rings), ...) for the start
    and the end: how far each pole lies past its end ring (metres) and how many shrinking rings
    lead to it. exponent 2 gives ellipses, larger values squarer sections.
    """
    c, lat, pal, h, s, poles, pole_arc = _with_caps(centres, lateral, palmar, half_axes, arc, caps)
    rings = ring_points(c, lat, pal, h, ring_size, exponent)
    n_rings = rings.shape[0]
    vertices = np.vstack((poles[0], rings.reshape(-1, 3), poles[1]))
    tip = vertices.shape[0] - 1
    faces = np.concatenate((
        _fan_faces(0, 1, ring_size, at_start=True),
        _strip_faces(n_rings, ring_size, 1),
        _fan_faces(tip, 1 + (n_rings - 1) * ring_size, ring_size, at_start=False),
    )).astype(np.int64)
    if signed_volume(vertices, faces) < 0.0:
        faces = faces[:, [0, 2, 1]]
    vertex_arc = np.concatenate(([pole_arc[0]], np.repeat(s, ring_size), [pole_arc[1]]))
    vertex_centres = np.vstack((poles[0], np.repeat(c, ring_size, axis=0), poles[1]))
    n_start = caps[0][1]
    ring_starts = 1 + (n_start + np.arange(centres.shape[0])) * ring_size
    return Loft(vertices, faces, vertex_arc, vertex_centres, ring_starts, ring_size, tip)
