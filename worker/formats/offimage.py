"""Points that leave the image: a track's keyframes rewritten so that formats with an
"outside" state (CVAT) say so instead of showing a position clamped to the border.

The annotation page stores positions inside the image (0 <= x < W), so a joint that leaves the
frame is labelled at the border, occluded. Where the solve places the joint outside the image,
the export replaces that stretch of the track by one keyframe without a position (CVAT writes it
outside=1, see :mod:`worker.formats.cvat`), keeping the values around it exactly: the frames
just before and just after the stretch get keyframes at the values the track had there.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from worker.tracks.interpolate import dense_track
from worker.tracks.keyframes import Keyframe, as_keyframes
from worker.tracks.spans import frame_spans


def _source_before(kfs: list[Keyframe], frame: int) -> Any:
    before = [k for k in kfs if k.frame <= frame]
    return before[-1].source if before else "placed"


def mark_outside(keyframes: Iterable[Any], outside: np.ndarray) -> list[Keyframe]:
    """One point's keyframes with every stretch where it is outside the image made a keyframe
    without a position.

    keyframes: what :func:`worker.tracks.keyframes.parse_keyframe` accepts, image px.
    outside: (F,) bool over the clip's F frames. Frames where the track has no position are
    left as they are.
    """
    kfs = as_keyframes(keyframes)
    outside = np.asarray(outside, dtype=bool)
    frames = len(outside)
    dense = dense_track(kfs, frames)
    placed = np.isfinite(dense.xy).all(axis=1)
    spans = frame_spans(outside & placed)
    if not spans:
        return kfs
    keyed = {k.frame: k for k in kfs}
    for start, end in spans:
        for f in range(start, end + 1):
            keyed.pop(f, None)
        keyed[start] = Keyframe(start, None, None, False)
        for f in (start - 1, end + 1):
            if 0 <= f < frames and f not in keyed and placed[f] and not outside[f]:
                x, y = (float(v) for v in dense.xy[f])
                keyed[f] = Keyframe(f, x, y, bool(dense.visible[f]), _source_before(kfs, f))
    return [keyed[f] for f in sorted(keyed)]
