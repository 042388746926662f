"""Cheap header checks of frame files, so a bad capture is refused before anything is copied."""

from __future__ import annotations

import struct
from pathlib import Path

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# JPEG start-of-frame markers that carry the image size (baseline, progressive, lossless...).
_SOF_MARKERS = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def jpeg_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a JPEG's start-of-frame segment, or None if it is not a JPEG."""
    if data[:2] != b"\xff\xd8":
        return None
    pos = 2
    while pos + 4 <= len(data):
        if data[pos] != 0xFF:
            return None
        marker = data[pos + 1]
        if marker == 0xFF:
            pos += 1
            continue
        length = struct.unpack(">H", data[pos + 2:pos + 4])[0]
        if marker in _SOF_MARKERS and pos + 9 <= len(data):
            height, width = struct.unpack(">HH", data[pos + 5:pos + 9])
            return width, height
        pos += 2 + length
    return None


def check_jpeg(path: Path, width: int, height: int) -> str | None:
    """None if ``path`` is a JPEG of the given size, else what is wrong with it."""
    with path.open("rb") as fh:
        head = fh.read(65536)
    size = jpeg_size(head)
    if size is None:
        return "not a readable JPEG image"
    if size != (width, height):
        return f"image is {size[0]}x{size[1]}, the camera's intrinsics say {width}x{height}"
    return None


def check_png16(path: Path, width: int, height: int) -> str | None:
    """None if ``path`` is a 16-bit single-channel PNG of the given size (depth in mm)."""
    with path.open("rb") as fh:
        head = fh.read(33)
    if len(head) < 33 or head[:8] != PNG_SIGNATURE or head[12:16] != b"IHDR":
        return "not a readable PNG image"
    w, h, bit_depth, colour_type = struct.unpack(">IIBB", head[16:26])
    if (w, h) != (width, height):
        return f"depth is {w}x{h}, the camera's intrinsics say {width}x{height}"
    if bit_depth != 16 or colour_type != 0:
        return "depth must be a 16-bit single-channel PNG (millimetres)"
    return None
