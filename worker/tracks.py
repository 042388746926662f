"""Annotation tracks: interpolation, completeness and plausibility checks, keyframe validation.

A track is one point of a task (a hand joint or an object landmark) through a clip of F frames,
stored as keyframes sorted by frame with positions in image pixels (x right, y down, 0 <= x <
width, 0 <= y < height). An occluded keyframe may carry a guessed position or none.

This is the twin of frontend/annotate/core/interpolate.js: same rules, same formula, same
messages. Both are checked against tests/fixtures/interpolation_golden.json.

Dense value at frame f:
    before the first keyframe (or no keyframes): unplaced, no position, not visible;
    at a keyframe: that keyframe;
    between keyframes k0 < f < k1: interpolated; visibility of k0; linear position when both have
        one, k0's position when only k0 has one, else none;
    after the last keyframe: the last keyframe's position and visibility, interpolated.

Provenance: a keyframe's source says where its position came from (SOURCES):
    "placed"     the worker put it there (the default; what a 4-element row means);
    "tracked"    an accepted tracking proposal, unchanged;
    "prefilled"  an accepted pre-fill suggestion (other views' consensus), unchanged;
    "edited"     came from a suggestion and the worker then changed it.
Stored rows are [frame, x, y, visible01], with a 5th element source only when it is not "placed",
so data without suggestions (and the golden vectors) keep their form. The page's store.js
writes the same rows.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from numbers import Real
from typing import Any, Literal, TypedDict, get_args

import numpy as np

STATE_UNPLACED = 0
STATE_KEYFRAME = 1
STATE_INTERPOLATED = 2
STATE_NAMES: tuple[str, ...] = ("unplaced", "keyframe", "interpolated")

# Radius (image px) within which all visible points of a frame count as one spot.
COLLAPSE_RADIUS_PX = 3.0
# Below this largest displacement (image px) over the clip, no point counts as moving.
STATIC_DISPLACEMENT_PX = 1.0
# A frame counts as collapsed only with at least this many visible points (fewer for 2-point
# tasks), so that two fingertips touching in a pinch do not trigger it.
COLLAPSE_MIN_POINTS = 3

KeyframeSource = Literal["placed", "tracked", "prefilled", "edited"]
# Every keyframe source, in the order messages list them.
SOURCES: tuple[KeyframeSource, ...] = get_args(KeyframeSource)
# Sources written as a 5th element of a stored row (all but the default).
_ROW_SOURCES = frozenset(SOURCES) - {"placed"}

# Per-frame source codes of keyframe_sources(); SOURCE_NAMES[code] is the name.
SOURCE_NONE = 0
SOURCE_PLACED = 1
SOURCE_TRACKED = 2
SOURCE_PREFILLED = 3
SOURCE_EDITED = 4
SOURCE_NAMES: tuple[str, ...] = ("none", "placed", "tracked", "prefilled", "edited")
# How much of the worker's own decision a source carries, for frames between two keyframes:
# placed > edited > tracked (a proposal between the worker's keyframes) > prefilled (from other
# views only). Between keyframes a frame takes the end carrying more of the worker's decision.
_DECISION_RANK = {
    SOURCE_PREFILLED: 0, SOURCE_TRACKED: 1, SOURCE_EDITED: 2, SOURCE_PLACED: 3,
}


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


@dataclass(frozen=True)
class DenseTrack:
    """A track's value at every frame.

    values: (F, 3) float64 [x, y, visible] with x, y in image px, NaN where there is no position,
        visible 1.0 or 0.0.
    state: (F,) int8, one of STATE_UNPLACED, STATE_KEYFRAME, STATE_INTERPOLATED.
    """

    values: np.ndarray
    state: np.ndarray

    @property
    def xy(self) -> np.ndarray:
        """(F, 2) image px, NaN where there is no position."""
        return self.values[:, :2]

    @property
    def visible(self) -> np.ndarray:
        """(F,) bool."""
        return self.values[:, 2] > 0.5

    def state_names(self) -> list[str]:
        return [STATE_NAMES[s] for s in self.state]


class Problem(TypedDict):
    point: int
    frames: list[list[int]]
    message: str


class Completeness(TypedDict):
    complete: bool
    problems: list[Problem]


class TrackWarning(TypedDict):
    kind: Literal["collapsed", "static"]
    frames: list[list[int]]
    message: str


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


def dense_track(keyframes: Iterable[Any], num_frames: int) -> DenseTrack:
    """The value of a track at every frame 0..num_frames-1 (see the module docstring).

    Args:
        keyframes: dicts {frame, x, y, visible} or compact [frame, x, y, visible01] lists, image px.
        num_frames: F, the clip length.
    """
    kfs = as_keyframes(keyframes)
    values = np.full((num_frames, 3), np.nan)
    values[:, 2] = 0.0
    state = np.full(num_frames, STATE_UNPLACED, dtype=np.int8)
    if not kfs or num_frames <= 0:
        return DenseTrack(values, state)
    k_frame = np.array([k.frame for k in kfs], dtype=np.float64)
    k_x = np.array([np.nan if k.x is None else k.x for k in kfs])
    k_y = np.array([np.nan if k.y is None else k.y for k in kfs])
    k_vis = np.array([1.0 if k.visible else 0.0 for k in kfs])

    frames = np.arange(num_frames, dtype=np.float64)
    i0 = np.searchsorted(k_frame, frames, side="right") - 1
    placed = i0 >= 0
    i0c = np.clip(i0, 0, len(kfs) - 1)
    i1c = np.clip(i0 + 1, 0, len(kfs) - 1)
    at_key = placed & (k_frame[i0c] == frames)
    has_next = placed & ~at_key & (i0 + 1 < len(kfs))

    x0, y0, x1, y1 = k_x[i0c], k_y[i0c], k_x[i1c], k_y[i1c]
    f0, f1 = k_frame[i0c], k_frame[i1c]
    lerp = has_next & ~np.isnan(x0) & ~np.isnan(x1)
    with np.errstate(invalid="ignore", divide="ignore"):
        # Same formula and operation order as interpolate.js, for bit-identical results.
        t = (frames - f0) / (f1 - f0)
        x_lerp = x0 + (x1 - x0) * t
        y_lerp = y0 + (y1 - y0) * t
    values[placed, 0] = np.where(lerp, x_lerp, x0)[placed]
    values[placed, 1] = np.where(lerp, y_lerp, y0)[placed]
    values[placed, 2] = k_vis[i0c][placed]
    state[placed] = STATE_INTERPOLATED
    state[at_key] = STATE_KEYFRAME
    return DenseTrack(values, state)


def dense_points(tracks: Iterable[tuple[int, Iterable[Any]]], num_frames: int,
                 num_points: int) -> tuple[np.ndarray, np.ndarray]:
    """A task's tracks, given as (point index, keyframes) pairs, at every frame.

    Returns (F, P, 2) image px (NaN where a point has no position) and (F, P) bool visibility;
    points without a track, or with an index outside 0..P-1, stay unplaced.
    """
    xy = np.full((num_frames, num_points, 2), np.nan)
    visible = np.zeros((num_frames, num_points), dtype=bool)
    for point, keyframes in tracks:
        if 0 <= point < num_points:
            dense = dense_track(keyframes, num_frames)
            xy[:, point], visible[:, point] = dense.xy, dense.visible
    return xy, visible


def frame_spans(flags: Sequence[bool] | np.ndarray) -> list[list[int]]:
    """Inclusive [start, end] spans of the frames where flags is true."""
    spans: list[list[int]] = []
    for f, flag in enumerate(flags):
        if not flag:
            continue
        if spans and spans[-1][1] == f - 1:
            spans[-1][1] = f
        else:
            spans.append([f, f])
    return spans


def format_spans(spans: list[list[int]]) -> str:
    """'frame 5' or 'frames 0-11, 20'."""
    single = len(spans) == 1 and spans[0][0] == spans[0][1]
    text = ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in spans)
    return f"{'frame' if single else 'frames'} {text}"


def _point_name(point_names: Sequence[str] | None, index: int) -> str:
    if point_names is not None and index < len(point_names):
        return point_names[index]
    return f"point {index}"


def _num_points(tracks: Sequence[Any], point_names: Sequence[str] | None) -> int:
    return len(point_names) if point_names is not None else len(tracks)


def completeness(
    tracks: Sequence[Iterable[Any]], num_frames: int, point_names: Sequence[str] | None = None
) -> Completeness:
    """Whether a task's tracks are ready to submit.

    Every point needs a keyframe, and each of its frames must be placed (a position, not
    unplaced) or occluded. Problems are reported per point with inclusive frame spans.

    Args:
        tracks: one keyframe list per point (dicts or compact lists), image px.
        num_frames: F.
        point_names: the task's point names; its length is the number of points.
    """
    problems: list[Problem] = []
    for p in range(_num_points(tracks, point_names)):
        keyframes = list(tracks[p]) if p < len(tracks) else []
        name = _point_name(point_names, p)
        if not keyframes:
            frames = [[0, num_frames - 1]] if num_frames > 0 else []
            problems.append({"point": p, "frames": frames, "message": f"{name}: no keyframes"})
            continue
        dense = dense_track(keyframes, num_frames)
        no_position = np.isnan(dense.values[:, 0]) | np.isnan(dense.values[:, 1])
        missing = (dense.state == STATE_UNPLACED) | (dense.visible & no_position)
        spans = frame_spans(missing)
        if spans:
            message = f"{name}: {format_spans(spans)} not placed"
            problems.append({"point": p, "frames": spans, "message": message})
    return {"complete": not problems, "problems": problems}


def _collapsed_frames(xy: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """(F,) bool: frames whose visible points all lie within COLLAPSE_RADIUS_PX of their centroid.

    xy: (N, F, 2) image px (NaN = no position); visible: (N, F) bool.
    """
    num_points, num_frames = visible.shape
    flags = np.zeros(num_frames, dtype=bool)
    if num_points < 2:
        return flags
    min_points = min(COLLAPSE_MIN_POINTS, num_points)
    usable = visible & ~np.isnan(xy).any(axis=2)
    for f in range(num_frames):
        pts = xy[usable[:, f], f]
        if len(pts) < min_points:
            continue
        centre = pts.mean(axis=0)
        flags[f] = bool(np.all(np.hypot(*(pts - centre).T) <= COLLAPSE_RADIUS_PX))
    return flags


def _largest_displacement(xy: np.ndarray) -> float | None:
    """Largest distance (image px) of a point's placed positions from its first placed one."""
    largest: float | None = None
    for track in xy:
        placed = track[~np.isnan(track).any(axis=1)]
        if len(placed) == 0:
            continue
        moved = float(np.max(np.hypot(*(placed - placed[0]).T)))
        largest = moved if largest is None else max(largest, moved)
    return largest


def suspicious(
    tracks: Sequence[Iterable[Any]], num_frames: int, point_names: Sequence[str] | None = None
) -> list[TrackWarning]:
    """Signs of careless work: frames where all visible points sit on one spot, or a clip where
    no point moves at all (when F > 1). Same arguments as completeness()."""
    num_points = _num_points(tracks, point_names)
    dense = [
        dense_track(list(tracks[p]) if p < len(tracks) else [], num_frames)
        for p in range(num_points)
    ]
    xy = np.stack([d.xy for d in dense]) if dense else np.zeros((0, num_frames, 2))
    visible = np.stack([d.visible for d in dense]) if dense else np.zeros((0, num_frames), bool)
    warnings: list[TrackWarning] = []
    spans = frame_spans(_collapsed_frames(xy, visible))
    if spans:
        radius = f"{COLLAPSE_RADIUS_PX:g}"
        message = f"all visible points within {radius} px of one spot in {format_spans(spans)}"
        warnings.append({"kind": "collapsed", "frames": spans, "message": message})
    moved = _largest_displacement(xy)
    if num_frames > 1 and moved is not None and moved < STATIC_DISPLACEMENT_PX:
        message = f"no point moves across the clip (all within {STATIC_DISPLACEMENT_PX:g} px)"
        warnings.append({"kind": "static", "frames": [[0, num_frames - 1]], "message": message})
    return warnings


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
        if type(row) is not list:
            return None
        if len(row) == 4:
            frame, x, y, visible = row
            source = None
        elif len(row) == 5:
            frame, x, y, visible, source = row
            if type(source) is not str:
                return None
            if source not in _ROW_SOURCES:
                if source != "placed":
                    return None
                source = None
        else:
            return None
        if type(frame) is not int or not previous < frame < num_frames:
            return None
        previous = frame
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
            if rows is not None:
                rows.append(row)
            continue
        if rows is None:
            rows = list(keyframes[:index])
        position = [None, None] if x is None else [float(x), float(y)]
        rows.append([frame, *position, seen] if source is None else
                    [frame, *position, seen, source])
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


def _source_codes(kfs: Sequence[Keyframe]) -> np.ndarray:
    codes = {name: code for code, name in enumerate(SOURCE_NAMES)}
    return np.array([codes[k.source] for k in kfs], dtype=np.int8)


def keyframe_sources(keyframes: Iterable[Any], num_frames: int) -> np.ndarray:
    """(F,) int8 source code (SOURCE_NAMES[code]) of the dense track at every frame.

    At a keyframe: its source. Between keyframes k0 < f < k1: of the two, the source carrying
    more of the worker's own decision (placed > edited > tracked > prefilled), so a span is
    "prefilled" only when both ends are, since the worker decided at least one end otherwise.
    After the last keyframe: its source (the position is held from it). Before the first
    keyframe, or with no keyframes: SOURCE_NONE.

    Args:
        keyframes: one track's keyframes, as :func:`parse_keyframe` accepts them.
        num_frames: F, the clip length.
    """
    kfs = as_keyframes(keyframes)
    out = np.full(max(num_frames, 0), SOURCE_NONE, dtype=np.int8)
    if not kfs or num_frames <= 0:
        return out
    k_frame = np.array([k.frame for k in kfs])
    k_code = _source_codes(kfs)
    rank = np.array([_DECISION_RANK[int(c)] for c in k_code])
    frames = np.arange(num_frames)
    i0 = np.searchsorted(k_frame, frames, side="right") - 1
    placed = i0 >= 0
    i0c = np.clip(i0, 0, len(kfs) - 1)
    i1c = np.clip(i0 + 1, 0, len(kfs) - 1)
    has_next = placed & (k_frame[i0c] != frames) & (i0 + 1 < len(kfs))
    take_next = has_next & (rank[i1c] > rank[i0c])
    out[placed] = np.where(take_next, k_code[i1c], k_code[i0c])[placed]
    return out


def decided_mask(keyframes: Iterable[Any], num_frames: int) -> np.ndarray:
    """(F,) bool: True where the track's value is the worker's own decision, i.e. not derived
    only from unedited pre-filled keyframes (and not unplaced). Tracked keyframes count as
    decided: tracking proposals run between the worker's own keyframes. QC scores these frames.

    Args:
        keyframes: one track's keyframes, as :func:`parse_keyframe` accepts them.
        num_frames: F, the clip length.
    """
    sources = keyframe_sources(keyframes, num_frames)
    return (sources != SOURCE_NONE) & (sources != SOURCE_PREFILLED)
