"""Interpolated stretches of a track checked against its own view's images.

Between two keyframes a track is a straight line (worker.tracks). Whether the point really
moved along that line is a question the view's images can answer: the point is tracked from
both keyframes inwards (worker.assist.lk: pyramidal Lucas-Kanade with its forward-backward
and appearance checks), and where the tracker holds, its position is compared with the line.
A stretch whose tracked path leaves the line by more than ``tolerance_px`` is one the images
say the track does not follow, and becomes an issue in words ("ring tip moves 14 px between
frames 4 and 8 that the track does not follow").

Each (frame, point) gets an evidence code (EVIDENCE_*): keyed by the worker, interpolated and
confirmed by the images, interpolated with no image evidence either way (the tracker lost the
point), interpolated where the images say the point moved away, or not labelled.

Conventions as worker.assist.lk: ``frames`` (F, H, W) uint8 grey images of one view, frame i
being clip frame ``first_frame + i``; keyframe rows ``[frame, x, y, visible01, ...]``; image
pixels, x right, y down. Pure: arrays in, arrays out.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from worker.assist.lk import propose, tracked_spans
from worker.tracks.interpolate import dense_points

# Evidence codes of one (frame, point) of a track.
EVIDENCE_NONE = 0          # no visible position there
EVIDENCE_KEYED = 1         # a keyframe: the worker decided the position on this frame
EVIDENCE_CONFIRMED = 2     # interpolated, and the images follow the line
EVIDENCE_UNCHECKED = 3     # interpolated, the tracker could not follow the point here
EVIDENCE_CONTRADICTED = 4  # interpolated, and the images say the point moved away from it
# How far (px) the tracked point may leave the line before the stretch is an issue: a careful
# worker keys where the path strays 2-3 px (worker.synth.annotators.FOLLOW_TOLERANCE_PX), LK
# on a held chain is good to about a pixel, and the keyframes' own noise (2 px per axis)
# moves both the line and the chains' starts alike; 6 px is twice what those add up to.
STRETCH_TOLERANCE_PX = 6.0


@dataclass(frozen=True)
class StretchIssue:
    """One stretch the images say the track does not follow.

    point: track index; first, last: its keyframes (clip frames); frame: where the tracked
    point is farthest from the line; offset_px: that distance, image px."""

    point: int
    first: int
    last: int
    frame: int
    offset_px: float

    def sentence(self, name: str) -> str:
        return (f"{name} moves {self.offset_px:.0f} px between frames {self.first} and "
                f"{self.last} that the track does not follow")

    def to_dict(self) -> dict[str, Any]:
        return {"point": self.point, "frames": [self.first, self.last], "frame": self.frame,
                "error_px": round(self.offset_px, 1), "about": "stretch"}


@dataclass
class StretchCheck:
    """evidence: (F, P) int8 EVIDENCE_* codes over the frames given; offset_px: (F, P) px,
    distance of the held tracked point from the line (NaN where none); issues: the stretches
    over tolerance, worst first."""

    evidence: np.ndarray
    offset_px: np.ndarray
    issues: list[StretchIssue] = field(default_factory=list)

    @property
    def contradicted(self) -> np.ndarray:
        """(F, P) bool: interpolated positions the images say are off the point's path."""
        return self.evidence == EVIDENCE_CONTRADICTED


def keyed_mask(keyframes: Sequence[Sequence[Any]], num_frames: int,
               first_frame: int = 0) -> np.ndarray:
    """(F, P) bool: frames first_frame.. that hold a keyframe of each point."""
    out = np.zeros((num_frames, len(keyframes)), dtype=bool)
    for point, rows in enumerate(keyframes):
        for row in rows:
            frame = int(row[0]) - first_frame
            if 0 <= frame < num_frames:
                out[frame, point] = True
    return out


def check_stretches(frames: np.ndarray, keyframes: Sequence[Sequence[Any]], *,
                    first_frame: int = 0,
                    tolerance_px: float = STRETCH_TOLERANCE_PX) -> StretchCheck:
    """Evidence codes and issues of P tracks over the frames given (see the module).

    frames: (F, H, W) uint8 grey; keyframes: P tracks of keyframe rows (clip frames).
    """
    count, points = int(np.shape(frames)[0]), len(keyframes)
    shifted = [[[int(r[0]) - first_frame, *r[1:]] for r in rows] for rows in keyframes]
    xy, visible = dense_points(enumerate(shifted), count, points)
    positioned = visible & np.isfinite(xy).all(axis=-1)
    keyed = keyed_mask(keyframes, count, first_frame) & positioned
    evidence = np.where(positioned, EVIDENCE_UNCHECKED, EVIDENCE_NONE).astype(np.int8)
    evidence[keyed] = EVIDENCE_KEYED
    offset = np.full((count, points), np.nan)
    issues: list[StretchIssue] = []
    if not tracked_spans(keyframes, first_frame, count):
        return StretchCheck(evidence, offset, issues)
    found = propose(frames, keyframes, first_frame=first_frame)
    held = found.ok & positioned & ~keyed
    offset[held] = np.linalg.norm(found.xy[held] - xy[held], axis=-1)
    evidence[held & (offset <= tolerance_px)] = EVIDENCE_CONFIRMED
    for point, k0, k1, _, _ in tracked_spans(keyframes, first_frame, count):
        inner = np.arange(k0 + 1 - first_frame, k1 - first_frame)
        span = offset[inner, point]
        if not np.isfinite(span).any() or np.nanmax(span) <= tolerance_px:
            continue
        worst = int(inner[int(np.nanargmax(span))])
        # The whole stretch is off the point's path, not only the frames the tracker held.
        evidence[inner, point] = np.where(positioned[inner, point], EVIDENCE_CONTRADICTED,
                                          EVIDENCE_NONE)
        issues.append(StretchIssue(point, k0, k1, worst + first_frame,
                                   float(offset[worst, point])))
    issues.sort(key=lambda i: -i.offset_px)
    return StretchCheck(evidence, offset, issues)
