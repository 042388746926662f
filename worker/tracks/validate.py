"""Validation of one track's saved keyframes: well formed, in the clip, sorted, inside the image.

What the annotation page sends passes one quick pass (:func:`checked_rows`); anything else gets
the full check, whose messages name each offending keyframe. Positions are image pixels.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from worker.tracks.keyframes import ROW_SOURCES, Keyframe, KeyframeError, parse_keyframe


def _keyframe_label(index: int, raw: Any) -> str:
    if isinstance(raw, dict):
        frame = raw.get("frame")
    else:
        frame = raw[0] if isinstance(raw, (list, tuple)) and raw else None
    return f"keyframe {index} (frame {frame!r})" if frame is not None else f"keyframe {index}"


def _position_problems(kf: Keyframe, width: int, height: int) -> list[str]:
    x, y = kf.x, kf.y
    if x is None or y is None:
        return ["visible keyframe has no position"] if kf.visible else []
    if not (math.isfinite(x) and math.isfinite(y)):
        return [f"position ({x}, {y}) is not finite"]
    problems = []
    if not 0 <= x < width:
        problems.append(f"x = {x:g} outside the image (0 <= x < {width})")
    if not 0 <= y < height:
        problems.append(f"y = {y:g} outside the image (0 <= y < {height})")
    return problems


def _plain_row(row: Any, width: int, height: int) -> tuple[int, list[Any] | None] | None:
    """One row of :func:`_plain_rows`: (frame, None) for a row already in its stored form,
    (frame, the stored row) for a plain row in another form, None for a row the full check
    must see (not a list of plain JSON values, or one that fails a check). The frame's range
    and order are the caller's to check."""
    if type(row) is not list:
        return None
    if len(row) == 4:
        frame, x, y, visible = row
        source = None
    elif len(row) == 5:
        frame, x, y, visible, source = row
        if type(source) is not str:
            return None
        if source not in ROW_SOURCES:
            if source != "placed":
                return None
            source = None
    else:
        return None
    if type(frame) is not int:
        return None
    if visible is True or (visible == 1 and type(visible) is int):
        seen = 1
    elif visible is False or (visible == 0 and type(visible) is int):
        seen = 0
    else:
        return None
    if x is None and y is None:
        if seen:
            return None
        as_sent = len(row) == 4 and type(visible) is int
    else:
        if (type(x) is not float and type(x) is not int) or (
                type(y) is not float and type(y) is not int):
            return None
        if not (0 <= x < width and 0 <= y < height):  # NaN fails here too
            return None
        as_sent = (len(row) == 4 and type(visible) is int and type(x) is float
                   and type(y) is float)
    if as_sent:
        return frame, None
    position = [None, None] if x is None else [float(x), float(y)]
    return frame, ([frame, *position, seen] if source is None else
                   [frame, *position, seen, source])


def _plain_rows(
    keyframes: Sequence[Any], num_frames: int, width: int, height: int
) -> list[list[Any]] | None:
    """The keyframes as stored ([frame, x, y, visible01] with float x, y, plus a source other
    than "placed") when every one is a list of plain JSON values that passes every check of
    :func:`validate_keyframes` (what the annotation page sends, in one quick pass); None sends
    them through the full check, which names each problem. Rows already in their stored form
    (what the page sends) are kept as sent: new rows are built only from the first one that
    is not."""
    rows: list[list[Any]] | None = None
    previous = -1
    for index, row in enumerate(keyframes):
        plain = _plain_row(row, width, height)
        if plain is None or not previous < plain[0] < num_frames:
            return None
        previous, stored = plain
        if stored is None:
            if rows is not None:
                rows.append(row)
            continue
        if rows is None:
            rows = list(keyframes[:index])
        rows.append(stored)
    if rows is None:
        return keyframes if type(keyframes) is list else list(keyframes)
    return rows


def _plainly_valid(keyframes: Sequence[Any], num_frames: int, width: int, height: int) -> bool:
    return _plain_rows(keyframes, num_frames, width, height) is not None


def checked_rows(
    keyframes: Sequence[Any], num_frames: int, width: int, height: int
) -> tuple[list[list[Any]], list[str]]:
    """(the keyframes as stored, []) when they pass :func:`validate_keyframes`, else ([], its
    problems). Stored form: sorted [frame, x, y, visible01] rows, x and y float px or None, with
    a 5th element source when it is not "placed" (see :meth:`Keyframe.row`)."""
    rows = _plain_rows(keyframes, num_frames, width, height)
    if rows is not None:
        return rows, []
    problems = validate_keyframes(keyframes, num_frames, width, height)
    if problems:
        return [], problems
    return [parse_keyframe(raw).row() for raw in keyframes], []


def validate_keyframes(
    keyframes: Sequence[Any], num_frames: int, width: int, height: int
) -> list[str]:
    """Problems with one track's keyframes, each naming the offending keyframe; [] when valid.

    Checks: well-formed entries (a known source, if any), frames in 0..num_frames-1, unique and
    sorted frames, finite positions inside the width x height image (px), and a position on every
    visible keyframe.
    """
    if _plainly_valid(keyframes, num_frames, width, height):
        return []
    problems: list[str] = []
    seen: dict[int, int] = {}
    previous: int | None = None
    for index, raw in enumerate(keyframes):
        found: list[str] = []
        try:
            kf = parse_keyframe(raw)
        except KeyframeError as exc:
            problems.append(f"{_keyframe_label(index, raw)}: {exc}")
            continue
        if not 0 <= kf.frame < num_frames:
            found.append(f"frame out of range 0-{num_frames - 1}")
        if kf.frame in seen:
            found.append(f"duplicate of keyframe {seen[kf.frame]} at the same frame")
        elif previous is not None and kf.frame < previous:
            found.append(f"not sorted by frame (follows frame {previous})")
        seen.setdefault(kf.frame, index)
        previous = kf.frame if previous is None else max(previous, kf.frame)
        found.extend(_position_problems(kf, width, height))
        if found:  # the label is only made for a keyframe with problems
            label = _keyframe_label(index, raw)
            problems.extend(f"{label}: {p}" for p in found)
    return problems
