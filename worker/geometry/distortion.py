"""OpenCV's radial-tangential lens distortion, written once for NumPy arrays and PyTorch tensors.

Coefficients ``dist`` (..., 5) = ``(k1, k2, p1, p2, k3)`` act on normalised coordinates
``x = X / Z, y = Y / Z`` of the camera frame (conventions in worker.geometry.cameras):

    r2 = x^2 + y^2,  radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3,
    xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2),
    yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y.

x and y come as separate arrays; dist's leading dimensions broadcast against them: (5,) for
one camera, (V, 5) against (..., V) for a stack of V cameras, (V, 1, 5) against (V, N). The
functions use only arithmetic and indexing, so the same code runs on NumPy arrays (the
projections of worker.geometry) and on PyTorch tensors with gradients (the solver's); terms
are added in OpenCV's order.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar

import numpy as np

if TYPE_CHECKING:
    import torch

Array = TypeVar("Array", np.ndarray, "torch.Tensor")


def _coefficients(dist: Array) -> tuple[Array, Array, Array, Array, Array]:
    return dist[..., 0], dist[..., 1], dist[..., 2], dist[..., 3], dist[..., 4]


def _radial(r2: Array, k1: Array, k2: Array, k3: Array) -> Array:
    return 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))


def _tangential(x: Array, y: Array, r2: Array, p1: Array, p2: Array
                ) -> tuple[tuple[Array, Array], tuple[Array, Array]]:
    """The two tangential terms of xd and of yd, kept apart so that each sum adds them in the
    same order wherever it is formed (bit-identical projections and inverses)."""
    return ((2.0 * p1 * x * y, p2 * (r2 + 2.0 * x * x)),
            (p1 * (r2 + 2.0 * y * y), 2.0 * p2 * x * y))


def distort(x: Array, y: Array, dist: Array) -> tuple[Array, Array]:
    """Distorted normalised coordinates (xd, yd) of undistorted ones (x, y), each (...)."""
    k1, k2, p1, p2, k3 = _coefficients(dist)
    r2 = x * x + y * y
    radial = _radial(r2, k1, k2, k3)
    (ax, bx), (ay, by) = _tangential(x, y, r2, p1, p2)
    return x * radial + ax + bx, y * radial + ay + by


def undistort(xd: Array, yd: Array, dist: Array, iterations: int) -> tuple[Array, Array]:
    """Invert :func:`distort` by fixed-point iteration, as OpenCV's undistortPoints does:
    (x, y) = ((xd, yd) - tangential(x, y)) / radial(x, y), starting from (xd, yd)."""
    k1, k2, p1, p2, k3 = _coefficients(dist)
    x, y = xd, yd
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = _radial(r2, k1, k2, k3)
        (ax, bx), (ay, by) = _tangential(x, y, r2, p1, p2)
        x, y = (xd - (ax + bx)) / radial, (yd - (ay + by)) / radial
    return x, y


def distort_partials(x: Array, y: Array, dist: Array
                     ) -> tuple[tuple[Array, Array], tuple[Array, Array]]:
    """The partial derivatives ((dxd/dx, dxd/dy), (dyd/dx, dyd/dy)) of :func:`distort`, each
    (...); arithmetic only, so NumPy arrays and PyTorch tensors alike."""
    k1, k2, p1, p2, k3 = _coefficients(dist)
    r2 = x * x + y * y
    radial = _radial(r2, k1, k2, k3)
    d_radial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    cross = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y
    return ((radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x, cross),
            (cross, radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x))


def distort_jacobian(x: np.ndarray, y: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """d(xd, yd) / d(x, y) of :func:`distort`: (..., 2, 2) for x, y (...) (NumPy)."""
    (a, b), (c, d) = distort_partials(x, y, dist)
    return np.stack((np.stack((a, b), axis=-1), np.stack((c, d), axis=-1)), axis=-2)
