"""Provenance at every frame: where a track's value came from, and which frames the worker
decided (see worker.tracks.keyframes for the sources).

QC scores only what the worker decided: a value derived only from unedited pre-filled
keyframes is the suggestion's own echo, not evidence.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from worker.tracks.keyframes import Keyframe, as_keyframes

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


def own_keyframes(tracks: Iterable[Iterable[Any]]) -> int:
    """How many of a label's keyframes the worker made or changed (placed, tracked from its
    own keyframes, or edited: a suggestion moved, or its visibility set), visible or hidden;
    0 when every keyframe is a pre-filled suggestion kept unchanged.

    Args:
        tracks: per point, keyframes as :func:`parse_keyframe` accepts them.
    """
    return sum(k.source != SOURCE_NAMES[SOURCE_PREFILLED]
               for track in tracks for k in as_keyframes(track))
