"""Check suggestions: a few suggestions per assignment shown deliberately off the point.

The annotation page offers suggestions (tracking proposals between keyframes, positions
pre-filled from the other views). A worker who accepts them without looking produces labels
that look good, since the suggestions are usually right. To tell such a worker from one who
checks, a handful of (point, frame) cells of every assignment are check cells: any suggestion
shown there is moved CHECK_OFFSET_PX off (in a direction drawn for the cell), far enough that
anyone looking at the frame sees it is wrong. A worker who looks drags it back (the keyframe
becomes "edited"); one who accepts everything keeps it (the keyframe stays "tracked" or
"prefilled"), which QC counts.

The cells and directions are drawn from a key and the assignment id alone (HMAC-SHA256), so
the suggestion routes, QC and the simulated crowd agree on them without storing anything, and
a worker cannot tell which cells they are. Never the first or last frame of the clip (the
worker keys those by hand).

Pure: numbers in, numbers out.
"""

from __future__ import annotations

import hashlib
import hmac
import math
import struct
from typing import Any

import numpy as np

# Check cells per assignment (fewer when the clip has too few inner frames).
CHECK_COUNT = 4
# How far off (image px) a check suggestion is shown: well beyond any careful worker's
# tolerance and far below the size of a hand in the frame.
CHECK_OFFSET_PX = 15.0
# Keyframe sources whose position the worker took from a suggestion unchanged.
ACCEPTED_SOURCES = ("tracked", "prefilled")


def check_key(signing_key: str) -> bytes:
    """The key check cells are drawn with, derived from the instance's signing key."""
    return hmac.new(signing_key.encode(), b"dexlabel check suggestions", hashlib.sha256).digest()


def _draw(key: bytes, *parts: object) -> bytes:
    message = "/".join(str(p) for p in parts).encode()
    return hmac.new(key, message, hashlib.sha256).digest()


def check_cells(key: bytes, assignment_id: int, num_points: int, num_frames: int,
                count: int = CHECK_COUNT) -> list[tuple[int, int]]:
    """The assignment's check cells, (point, frame) pairs sorted, distinct, with frames in
    1..num_frames-2 and at most one per frame; [] for clips under 3 frames."""
    inner = num_frames - 2
    if inner < 1 or num_points < 1:
        return []
    count = min(count, inner)
    cells: dict[int, int] = {}
    attempt = 0
    while len(cells) < count:
        point, frame = struct.unpack(">II", _draw(key, "cell", assignment_id, attempt)[:8])
        frame = 1 + frame % inner
        if frame not in cells:
            cells[frame] = point % num_points
        attempt += 1
    return sorted((point, frame) for frame, point in cells.items())


def check_offset(key: bytes, assignment_id: int, point: int, frame: int) -> tuple[float, float]:
    """(dx, dy) image px a suggestion at this cell is shown off by (length CHECK_OFFSET_PX)."""
    (turn,) = struct.unpack(">I", _draw(key, "offset", assignment_id, point, frame)[:4])
    angle = 2 * math.pi * turn / 2**32
    return CHECK_OFFSET_PX * math.cos(angle), CHECK_OFFSET_PX * math.sin(angle)


def shift_inside(x: float, y: float, dx: float, dy: float, width: int,
                 height: int) -> tuple[float, float]:
    """(x, y) moved by (dx, dy); where that leaves the image, moved the other way instead."""
    def inside(u: float, v: float) -> bool:
        return 0 <= u <= width - 1 and 0 <= v <= height - 1
    for sx, sy in ((dx, dy), (-dx, -dy), (-dy, dx), (dy, -dx)):
        if inside(x + sx, y + sy):
            return x + sx, y + sy
    return float(min(max(x + dx, 0), width - 1)), float(min(max(y + dy, 0), height - 1))


def plant(key: bytes, assignment_id: int, xy: np.ndarray, shown: np.ndarray, first_frame: int,
          num_frames: int, num_points: int, width: int, height: int,
          points: list[int] | None = None) -> np.ndarray:
    """Suggestions with the assignment's check cells moved off.

    xy: (P, R, 2) suggested positions, image px, for R frames starting at ``first_frame``
    (NaN where there is none); shown: (P, R) bool, where a suggestion is offered (a check cell
    elsewhere is left alone); num_frames, num_points: the task's clip length and point count
    (the cells depend on them, not on what was asked for); points: the task point index of
    each row of xy (default 0..P-1). Returns a copy of xy.
    """
    out = np.array(xy, dtype=np.float64, copy=True)
    rows = list(range(out.shape[0])) if points is None else list(points)
    row_of = {point: i for i, point in enumerate(rows)}
    for point, frame in check_cells(key, assignment_id, num_points, num_frames):
        i, r = row_of.get(point), frame - first_frame
        if i is None or not 0 <= r < out.shape[1] or not shown[i, r]:
            continue
        x, y = out[i, r]
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        dx, dy = check_offset(key, assignment_id, point, frame)
        out[i, r] = shift_inside(float(x), float(y), dx, dy, width, height)
    return out


def _cell_outcomes(key: bytes, assignment_id: int, tracks: list[list[list[Any]]],
                   num_points: int, num_frames: int) -> list[tuple[int, int, str]]:
    """(point, frame, "accepted" | "corrected") of each check cell that is either."""
    out = []
    for point, frame in check_cells(key, assignment_id, num_points, num_frames):
        if point >= len(tracks):
            continue
        for row in tracks[point]:
            if row[0] != frame:
                continue
            source = row[4] if len(row) > 4 else "placed"
            if source in ACCEPTED_SOURCES and row[3]:
                out.append((point, frame, "accepted"))
            elif source == "edited":
                out.append((point, frame, "corrected"))
            break
    return out


def accepted_checks(key: bytes, assignment_id: int, tracks: list[list[list[Any]]], num_points: int,
                    num_frames: int) -> tuple[int, int]:
    """(accepted, corrected) check cells of a saved assignment.

    tracks: per point, keyframe rows ``[frame, x, y, visible01]`` or ``[frame, x, y,
    visible01, source]`` (worker.tracks). A check cell whose keyframe came from a suggestion
    unchanged (source "tracked" or "prefilled") and is visible was accepted (a suggestion
    shown occluded is never moved off, so keeping it says nothing); one whose keyframe is
    "edited" was corrected; cells without such a keyframe (keyed by hand, interpolated, never
    suggested) count as neither.
    """
    outcomes = [o for _, _, o in _cell_outcomes(key, assignment_id, tracks, num_points,
                                                num_frames)]
    return outcomes.count("accepted"), outcomes.count("corrected")


def kept_checks(key: bytes, assignment_id: int, tracks: list[list[list[Any]]], num_points: int,
                num_frames: int) -> list[tuple[int, int]]:
    """The (point, frame) check cells of a saved assignment accepted unchanged (as
    :func:`accepted_checks` counts them), sorted: what a rejection names."""
    return [(p, f) for p, f, o in _cell_outcomes(key, assignment_id, tracks, num_points,
                                                 num_frames) if o == "accepted"]
