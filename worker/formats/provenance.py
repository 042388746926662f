"""Per-frame provenance of a target's labels, as every export format carries it.

Pure: keyframes in, per view and frame a state word and per frame a count of views out.

A view's label of a target (a hand's 21 joints, an object's 2 landmarks) at a frame is in one
of these states, taken over the points that have a position there (keyframes at that frame, or
positions the track model interpolates or holds; see :mod:`worker.tracks`):

- ``"keyframed"``: the worker put the point there (a keyframe placed or edited by hand);
- ``"tracked"``: a keyframe the point tracker proposed and the worker kept (source tracked);
- ``"prefilled"``: a keyframe suggested from the other views' consensus and kept (prefilled);
- ``"interpolated"``: no keyframe at that frame: the position comes from the keyframes around;
- ``"none"``: no point of the target has a position there (not labelled in that view).

The view's state is the state of most of its positioned points; a tie goes to the state higher
in the list above. ``views_decided`` counts, per frame, the views whose state is keyframed or
tracked: views whose own images decided the frame (a prefilled position came from the other
views, an interpolated one from other frames); ``deciding_views`` names them, and
``frame_actions`` says how many of the accepted work's human actions each frame took.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, Literal

import numpy as np

from worker.tracks.interpolate import dense_track
from worker.tracks.keyframes import as_keyframes

ProvenanceState = Literal["keyframed", "tracked", "prefilled", "interpolated", "none"]
STATES: tuple[ProvenanceState, ...] = ("keyframed", "tracked", "prefilled", "interpolated",
                                       "none")
DECIDING_STATES: tuple[ProvenanceState, ...] = ("keyframed", "tracked")
_STATE_OF_SOURCE = {"placed": 0, "edited": 0, "tracked": 1, "prefilled": 2}
_INTERPOLATED, _NONE = 3, 4


def view_states(points: Sequence[Iterable[Any]], num_frames: int) -> list[ProvenanceState]:
    """The state (see the module docstring) of one view's label of one target at each frame.

    points: per point its keyframes (stored rows [frame, x, y, visible01(, source)], dicts or
    :class:`worker.tracks.keyframes.Keyframe`). Returns ``num_frames`` state words.
    """
    if num_frames < 0:
        raise ValueError(f"num_frames must be >= 0, got {num_frames}")
    votes = np.zeros((num_frames, len(STATES) - 1), dtype=np.int64)
    for keyframes in points:
        kfs = as_keyframes(keyframes)
        state = np.full(num_frames, _INTERPOLATED)
        for kf in kfs:
            if 0 <= kf.frame < num_frames and kf.has_position:
                state[kf.frame] = _STATE_OF_SOURCE[kf.source]
        placed = np.isfinite(dense_track(kfs, num_frames).xy).all(axis=1)
        rows = np.flatnonzero(placed)
        np.add.at(votes, (rows, state[rows]), 1)
    # argmax takes the first of equal counts: the state higher in STATES.
    return [STATES[int(np.argmax(row))] if row.any() else STATES[_NONE] for row in votes]


def views_decided(states: Sequence[Sequence[str]]) -> list[int]:
    """Per frame, how many views' states (V lists of F words) are keyframed or tracked."""
    if not states:
        return []
    table = np.asarray([[s in DECIDING_STATES for s in view] for view in states], dtype=bool)
    return [int(n) for n in table.sum(axis=0)]


def frame_provenance(states: Sequence[Sequence[str]], serials: Sequence[str],
                     frame: int) -> dict[str, Any]:
    """One frame's provenance as written into COCO, BOP and JSON records:
    ``{"views_decided": n, "views": {serial: state}}`` (views without a label are left out)."""
    views = {str(serial): view[frame] for serial, view in zip(serials, states, strict=True)
             if view[frame] != "none"}
    decided = sum(state in DECIDING_STATES for state in views.values())
    return {"views_decided": int(decided), "views": views}


def deciding_views(states: Sequence[Sequence[str]], serials: Sequence[str]) -> list[list[str]]:
    """Per frame, the serials of the views (V lists of F state words) whose own keyframe
    (keyframed or tracked) decided it."""
    if not states:
        return []
    return [[str(serial) for serial, view in zip(serials, states, strict=True)
             if view[f] in DECIDING_STATES] for f in range(len(states[0]))]


def frame_actions(work: Iterable[tuple[int, Sequence[Iterable[Any]]]],
                  num_frames: int) -> np.ndarray:
    """(F,) float: the human actions attributable to each frame of a target.

    work: per accepted assignment of the target (any view), its edit actions (clicks, drags,
    keys the annotation page counted) and its points' keyframes. An assignment's actions are
    shared equally among all its keyframes (every point, every source: a kept suggestion
    took a keystroke as a placed point took a click); a frame gets the shares of the keyframes
    at it. An assignment without a keyframe in the clip shares its actions equally among all
    frames. Summed over the frames, the result is the accepted work's actions.
    """
    if num_frames < 0:
        raise ValueError(f"num_frames must be >= 0, got {num_frames}")
    out = np.zeros(num_frames, dtype=np.float64)
    if num_frames == 0:
        return out
    for actions, points in work:
        if actions < 0:
            raise ValueError(f"an assignment's actions must be >= 0, got {actions}")
        counts = np.zeros(num_frames, dtype=np.float64)
        for keyframes in points:
            for kf in as_keyframes(keyframes):
                if 0 <= kf.frame < num_frames:
                    counts[kf.frame] += 1
        total = counts.sum()
        out += actions * (counts / total if total else np.full(num_frames, 1.0 / num_frames))
    return out
