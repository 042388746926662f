"""Keyframes: the rows a track is stored as, and the forms the routes and formats accept.

Positions are image pixels (x right, y down). Provenance: a keyframe's source says where its
position came from (SOURCES):
    "placed"     the worker put it there (the default; what a 4-element row means);
    "tracked"    an accepted tracking proposal, unchanged;
    "prefilled"  an accepted pre-fill suggestion (other views' consensus), unchanged;
    "edited"     came from a suggestion and the worker then changed it.
Stored rows are [frame, x, y, visible01], with a 5th element source only when it is not "placed",
so data without suggestions (and the golden vectors) keep their form. The page's store.js
writes the same rows.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from numbers import Real
from typing import Any, Literal, get_args

import numpy as np

KeyframeSource = Literal["placed", "tracked", "prefilled", "edited"]
# Every keyframe source, in the order messages list them.
SOURCES: tuple[KeyframeSource, ...] = get_args(KeyframeSource)
# Sources written as a 5th element of a stored row (all but the default).
ROW_SOURCES = frozenset(SOURCES) - {"placed"}


class KeyframeError(ValueError):
    """A keyframe that is not {frame, x, y, visible[, source]} / [frame, x, y, visible01[, source]]
    with valid types."""


@dataclass(frozen=True)
class Keyframe:
    """One keyframe: frame index, position in image px (None when occluded without a guess),
    visibility and source (see the module docstring)."""

    frame: int
    x: float | None
    y: float | None
    visible: bool
    source: KeyframeSource = "placed"

    @property
    def has_position(self) -> bool:
        return self.x is not None and self.y is not None

    def row(self) -> list[Any]:
        """The stored form: [frame, x, y, visible01], plus source when it is not "placed"."""
        row: list[Any] = [self.frame, self.x, self.y, 1 if self.visible else 0]
        if self.source != "placed":
            row.append(self.source)
        return row


def _number_or_none(value: Any, field: str) -> float | None:
    if value is None:
        return None
    if type(value) is float:  # what JSON gives: the common case, fast
        return value
    if isinstance(value, bool) or not isinstance(value, Real):
        raise KeyframeError(f"{field} must be a number or null, got {value!r}")
    try:
        return float(value)
    except OverflowError:  # an integer beyond any float, e.g. 10**400
        raise KeyframeError(f"{field} is too large for a position") from None


def _source(value: Any) -> KeyframeSource:
    if type(value) is not str or value not in SOURCES:
        raise KeyframeError(f"source must be one of {', '.join(SOURCES)}, got {value!r}")
    return value  # one of SOURCES: a KeyframeSource


def parse_keyframe(raw: Any) -> Keyframe:
    """A keyframe from a dict {frame, x, y, visible[, source]} or a compact
    [frame, x, y, visible01[, source]] list; without a source it is "placed".

    Raises:
        KeyframeError: naming the malformed field.
    """
    if isinstance(raw, Keyframe):
        return raw
    source: Any = "placed"
    if isinstance(raw, dict):
        missing = [k for k in ("frame", "visible") if k not in raw]
        if missing:
            raise KeyframeError(f"missing {', '.join(missing)}")
        # An occluded keyframe without a guess may leave out x and y.
        frame, x, y, visible = raw["frame"], raw.get("x"), raw.get("y"), raw["visible"]
        source = raw.get("source", "placed")
    elif isinstance(raw, (list, tuple)) and len(raw) == 4:
        frame, x, y, visible = raw
    elif isinstance(raw, (list, tuple)) and len(raw) == 5:
        frame, x, y, visible, source = raw
    else:
        expected = ("{frame, x, y, visible[, source]} or [frame, x, y, visible01] or "
                    "[frame, x, y, visible01, source]")
        raise KeyframeError(f"expected {expected}, got {raw!r}")
    if type(frame) is not int and (isinstance(frame, bool)
                                   or not isinstance(frame, (int, np.integer))):
        raise KeyframeError(f"frame must be an integer, got {frame!r}")
    if visible not in (True, False, 0, 1):
        raise KeyframeError(f"visible must be a boolean or 0/1, got {visible!r}")
    x_value, y_value = _number_or_none(x, "x"), _number_or_none(y, "y")
    if (x_value is None) != (y_value is None):
        raise KeyframeError("x and y must both be numbers or both be null")
    return Keyframe(int(frame), x_value, y_value, bool(visible), _source(source))


def as_keyframes(raw: Iterable[Any]) -> list[Keyframe]:
    """Parses keyframes (dicts or compact lists) and sorts them by frame."""
    return sorted((parse_keyframe(k) for k in raw), key=lambda k: k.frame)
