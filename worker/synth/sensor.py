"""Sensor effects of an Intel RealSense D415-like RGB-D camera on rendered images.

Depth: an active stereo camera's depth error grows with the square of the distance,
``sigma_z = z^2 * subpixel / (f * baseline)``; D415's baseline is 55 mm and its stereo matcher
reaches about 0.08 px subpixel accuracy, which gives ~1 mm at 0.7 m for a 615 px focal length.
Pixels near depth discontinuities are often invalid (occlusion shadows and matcher failures),
and small blobs drop out at random; invalid pixels read 0, as in the real aligned depth stream.
"""

from __future__ import annotations

from statistics import NormalDist

import cv2
import numpy as np

D415_BASELINE_M = 0.055
D415_SUBPIXEL = 0.08
D415_MIN_DEPTH_M = 0.16  # closer than the D415's minimum range reads as no depth
D415_MAX_DEPTH_M = 6.0
EDGE_JUMP_M = 0.015  # a neighbour this much nearer or farther marks a depth edge
EDGE_DROP_PROBABILITY = 0.55
# Standard-normal level exceeded with EDGE_DROP_PROBABILITY.
_EDGE_DROP_QUANTILE = NormalDist().inv_cdf(1.0 - EDGE_DROP_PROBABILITY)
COLOR_NOISE_SIGMA = 1.8  # 8-bit grey levels of per-pixel read noise


def depth_sigma_m(depth_m: np.ndarray, focal_px: float) -> np.ndarray:
    """Standard deviation (metres) of the stereo depth error at depth (H, W) metres."""
    return depth_m * depth_m * D415_SUBPIXEL / (focal_px * D415_BASELINE_M)


def _depth_edges(depth_m: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels with a 4-neighbour whose depth differs by more than EDGE_JUMP_M."""
    valid = depth_m > 0
    # Background (0) counts as infinitely far, so object silhouettes against it are edges too.
    d = np.where(valid, depth_m, 1e3)
    edge = np.zeros(d.shape, bool)
    jump_x = np.abs(np.diff(d, axis=1)) > EDGE_JUMP_M
    jump_y = np.abs(np.diff(d, axis=0)) > EDGE_JUMP_M
    edge[:, 1:] |= jump_x
    edge[:, :-1] |= jump_x
    edge[1:, :] |= jump_y
    edge[:-1, :] |= jump_y
    return edge & valid


def _blob_holes(shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """(H, W) bool mask of a few small elliptical dropouts, sizes scaled to the image."""
    h, w = shape
    mask = np.zeros(shape, np.uint8)
    scale = w / 640.0
    for _ in range(int(rng.poisson(7))):
        centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        axes = (max(1, int(rng.uniform(1.5, 7) * scale)), max(1, int(rng.uniform(1.5, 5) * scale)))
        cv2.ellipse(mask, centre, axes, float(rng.uniform(0, 180)), 0, 360, 1, -1)
    return mask.astype(bool)


def simulate_depth(depth_m: np.ndarray, focal_px: float, rng: np.random.Generator) -> np.ndarray:
    """Rendered depth (H, W) metres along camera z (0 = nothing) -> sensor depth (H, W) uint16 mm.

    Adds distance-dependent Gaussian noise, drops clumps of pixels along depth edges and a few
    random blobs, clips to the sensor's range and quantises to millimetres (0 = no depth).
    """
    depth_m = np.asarray(depth_m, dtype=np.float64)
    valid = (depth_m > D415_MIN_DEPTH_M) & (depth_m < D415_MAX_DEPTH_M)
    noise = rng.standard_normal(depth_m.shape, dtype=np.float32)
    noisy = depth_m + noise * depth_sigma_m(depth_m, focal_px)
    band = cv2.dilate(_depth_edges(depth_m).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    # Low-pass filtered noise makes the edge dropouts come in clumps rather than single pixels.
    clump = cv2.GaussianBlur(rng.standard_normal(depth_m.shape, dtype=np.float32), (0, 0), 1.5)
    holes = (band & (clump > _EDGE_DROP_QUANTILE * clump.std())) | _blob_holes(depth_m.shape, rng)
    keep = valid & ~holes
    mm = np.rint(np.where(keep, noisy, 0.0) * 1000.0)
    return np.clip(mm, 0, np.iinfo(np.uint16).max).astype(np.uint16)


def finish_color(linear_bgr: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Shaded image (H, W, 3) float in [0, 255] -> camera image (H, W, 3) uint8 BGR.

    A slight blur stands in for lens softness and anti-aliasing; read noise is added after it.
    """
    img: np.ndarray = cv2.GaussianBlur(linear_bgr.astype(np.float32), (0, 0), 0.6)
    img += rng.standard_normal(img.shape, dtype=np.float32) * np.float32(COLOR_NOISE_SIGMA)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)
