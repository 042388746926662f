"""Dataset-wide constants of the DexYCB layout; their home is worker.formats.dexycb."""

from __future__ import annotations

from worker.formats.dexycb import (
    FPS,
    HAND_SEG_VALUE,
    IMAGE_HEIGHT,
    IMAGE_WIDTH,
    YCB_CLASSES,
)

__all__ = ["FPS", "HAND_SEG_VALUE", "IMAGE_HEIGHT", "IMAGE_WIDTH", "YCB_CLASSES"]
