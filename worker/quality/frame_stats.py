"""Per-frame image statistics: exposure, sharpness and depth coverage of one view's frame."""

from __future__ import annotations

import cv2
import numpy as np

THUMB_MAX_SIDE = 160


def frame_statistics(color_bgr: np.ndarray, depth_mm: np.ndarray | None) -> dict[str, float]:
    """Summary numbers of one frame.

    Args:
        color_bgr: (H, W, 3) uint8 colour image.
        depth_mm: (H, W) uint16 depth in millimetres along the camera's z axis, 0 = no reading,
            or None for a view without depth.

    Returns:
        brightness (mean grey level, 0-255), contrast (its standard deviation), sharpness
        (variance of the Laplacian, higher is sharper), and with depth: depth_coverage (fraction
        of pixels with a reading) and depth_median_mm.
    """
    if color_bgr.ndim != 3 or color_bgr.shape[2] != 3:
        raise ValueError(f"color_bgr must have shape (H, W, 3), got {color_bgr.shape}")
    grey = cv2.cvtColor(color_bgr, cv2.COLOR_BGR2GRAY)
    stats = {
        "brightness": float(grey.mean()),
        "contrast": float(grey.std()),
        "sharpness": float(cv2.Laplacian(grey, cv2.CV_64F).var()),
    }
    if depth_mm is not None:
        if depth_mm.shape != grey.shape:
            raise ValueError(f"depth_mm must have shape {grey.shape}, got {depth_mm.shape}")
        valid = depth_mm > 0
        stats["depth_coverage"] = float(valid.mean())
        stats["depth_median_mm"] = float(np.median(depth_mm[valid])) if valid.any() else 0.0
    return stats


def thumbnail_jpeg(color_bgr: np.ndarray, max_side: int = THUMB_MAX_SIDE) -> bytes:
    """A small JPEG of the frame whose longer side is ``max_side`` pixels."""
    h, w = color_bgr.shape[:2]
    scale = max_side / max(h, w)
    small = cv2.resize(color_bgr, (max(1, round(w * scale)), max(1, round(h * scale))),
                       interpolation=cv2.INTER_AREA)
    return cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, 85])[1].tobytes()
