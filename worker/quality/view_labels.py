"""One assignment's labels of one view, as QC takes them: positions, visibility, and which
positions are the worker's own decisions (a pre-filled suggestion left unchanged is not)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.cameras import CameraModel


@dataclass
class ViewLabels:
    """One assignment's labels of one view.

    key: the assignment's id. view: index into the cameras list.
    xy: (F, P, 2) image px, NaN where there is no position. visible: (F, P) bool.
    working_time_s: the worker's active time, seconds, if known.
    decided: (F, P) bool, where the position is the worker's own decision (placed, edited or
        a tracking proposal from this view's images accepted); False where it only comes
        from suggestions pre-filled from the other views and left unchanged
        (worker.tracks.sources.decided_mask). None: all of it (work without provenance). Undecided
        positions never enter the consensus and are never scored, so a view pre-filled from
        the others cannot agree with them by construction (leave-one-out holds).
    """

    key: str
    view: int
    xy: np.ndarray
    visible: np.ndarray
    working_time_s: float | None = None
    decided: np.ndarray | None = None


def check_labels(cameras: list[CameraModel], labels: list[ViewLabels]) -> tuple[int, int]:
    """(F, P) shared by all labels; ValueError naming the field and shape otherwise."""
    if not labels:
        raise ValueError("labels must not be empty")
    frames, points = np.shape(labels[0].xy)[:2]
    keys = set()
    for lab in labels:
        xy, vis = np.shape(lab.xy), np.shape(lab.visible)
        if xy != (frames, points, 2) or vis != (frames, points):
            raise ValueError(f"labels {lab.key!r}: xy must have shape (F={frames}, P={points}, 2) "
                             f"and visible (F, P), got {xy} and {vis}")
        if not 0 <= lab.view < len(cameras):
            raise ValueError(f"labels {lab.key!r}: view {lab.view} is not in 0..{len(cameras) - 1}")
        if lab.decided is not None and np.shape(lab.decided) != (frames, points):
            raise ValueError(f"labels {lab.key!r}: decided must have shape (F={frames}, "
                             f"P={points}), got {np.shape(lab.decided)}")
        if lab.key in keys:
            raise ValueError(f"labels: key {lab.key!r} appears twice")
        keys.add(lab.key)
    return frames, points


def decided_of(lab: ViewLabels) -> np.ndarray:
    """(F, P) bool: where the label's position is the worker's own decision (everywhere for a
    label without provenance)."""
    if lab.decided is None:
        return np.ones(np.shape(lab.visible), bool)
    return np.asarray(lab.decided, bool)


def decided_xy(lab: ViewLabels) -> np.ndarray:
    """(F, P, 2) px of the label's own decisions, NaN where it has none or only suggestions."""
    return np.where(decided_of(lab)[..., None], np.asarray(lab.xy, dtype=np.float64), np.nan)


def observed_xy(lab: ViewLabels) -> np.ndarray:
    """(F, P, 2) px of the label's visible points that the worker decided, NaN elsewhere
    (pre-filled suggestions are the other views' consensus, not an observation of this one;
    a hidden point's stored position is no observation either)."""
    return np.where(np.asarray(lab.visible, bool)[..., None], decided_xy(lab), np.nan)


def observations(labels: list[ViewLabels]) -> np.ndarray:
    """(F*P, L, 2) px of every label's observed_xy, one column per label."""
    cols = [observed_xy(lab) for lab in labels]
    return np.stack(cols, axis=2).reshape(-1, len(labels), 2)
