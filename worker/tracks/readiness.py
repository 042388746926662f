"""Whether a task's tracks are ready to submit (every frame placed or occluded), and signs of
careless work (all points on one spot, nothing moving). Positions are image pixels; the messages
are the ones the annotation page shows (frontend/annotate/core/interpolate.js).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, Literal, TypedDict

import numpy as np

from worker.tracks.interpolate import STATE_UNPLACED, dense_track
from worker.tracks.spans import format_spans, frame_spans

# Radius (image px) within which all visible points of a frame count as one spot.
COLLAPSE_RADIUS_PX = 3.0
# Below this largest displacement (image px) over the clip, no point counts as moving.
STATIC_DISPLACEMENT_PX = 1.0
# A frame counts as collapsed only with at least this many visible points (fewer for 2-point
# tasks), so that two fingertips touching in a pinch do not trigger it.
COLLAPSE_MIN_POINTS = 3


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
