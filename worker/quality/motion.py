"""A target's motion as the other labels show it: what a frozen track is compared with.

A label that copies one frame to all (the "lazy" worker) stays still while the hand or the
object moves. Without a multi-view reference (too few views agree to triangulate), the
other labels' own tracks still show that the target moves: each view sees the motion at its
own scale, but all see it. Pixels x right, y down; each track in its own view.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.quality.metrics import num


def track_motion(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """A label's motion: (F-1,) median step of its landmarks, px (NaN where unknown), and the
    largest median distance of its landmarks from where they were first placed, px."""
    step = np.linalg.norm(np.diff(xy, axis=0), axis=-1)
    first = np.full(xy.shape[1:], np.nan)
    for p in range(xy.shape[1]):
        placed = np.flatnonzero(np.isfinite(xy[:, p]).all(axis=-1))
        if placed.size:
            first[p] = xy[placed[0], p]
    dist = np.linalg.norm(xy - first, axis=-1)
    has_step, has_dist = np.isfinite(step).any(axis=1), np.isfinite(dist).any(axis=1)
    med_step = np.full(step.shape[0], np.nan)
    if has_step.any():
        med_step[has_step] = np.nanmedian(step[has_step], axis=1)
    reach = float(np.nanmedian(dist[has_dist], axis=1).max()) if has_dist.any() else 0.0
    return med_step, reach


@dataclass
class TargetMotion:
    """How the OTHER labels of a target see it move: step (F-1,) px, their median per-frame
    step; reach px, their median largest distance from the first position; jitter px per
    frame^2, their median track_jitter (None where unknown)."""

    step: np.ndarray
    reach: float
    jitter: float | None = None


# A track that shakes more than this (px per frame^2) is random clicks, not a witness of the
# target's motion: careful tracks shake 1.4-2.6 at 30 fps, sloppy ones ~4, random ones ~70.
WITNESS_JITTER_PX = 15.0
# One that shakes less is frozen (one frame copied to all): it witnesses no motion either.
FROZEN_JITTER_PX = 0.05
# A label is compared with the target's motion only where it shows its points over at least
# this share of the target's travel (the other labels' per-frame steps summed): a one-frame
# copy shows them throughout, a careful label of hidden points only where they show.
SEEN_TRAVEL_SHARE = 0.5


def others_motion(tracks: dict[str, np.ndarray], silent: frozenset[str] = frozenset()
                  ) -> dict[str, TargetMotion | None]:
    """For each label key, the target's motion as the other labels' tracks (F, P, 2) px show
    it (random tracks, see WITNESS_JITTER_PX, and the ``silent`` keys left out); None with
    fewer than two others."""
    motions = {key: track_motion(xy) for key, xy in tracks.items()}
    shakes = {key: track_jitter(xy) for key, xy in tracks.items()}
    witnesses = {key for key, shake in shakes.items()
                 if (shake or 0.0) <= WITNESS_JITTER_PX and key not in silent}
    moving = {key for key in witnesses if (shakes[key] or 0.0) > FROZEN_JITTER_PX}
    out: dict[str, TargetMotion | None] = {}
    for key in motions:
        others = [m for k, m in motions.items() if k != key and k in witnesses]
        if len(others) < 2:
            out[key] = None
            continue
        steps = np.stack([m[0] for m in others])
        has = np.isfinite(steps).any(axis=0)
        step = np.full(steps.shape[1], np.nan)
        step[has] = np.nanmedian(steps[:, has], axis=0)
        known = [v for k, v in shakes.items() if k != key and k in moving and v is not None]
        out[key] = TargetMotion(step=step, reach=float(np.median([m[1] for m in others])),
                                jitter=float(np.median(known)) if known else None)
    return out


def moved_with(xy: np.ndarray, motion: TargetMotion, moves_px: float,
               shown: np.ndarray | None = None) -> float | None:
    """How far the label's points (F, P, 2) px travel compared with the other labels' (1 = as
    far or farther), when the target clearly moves (the others reach ``moves_px``); None
    for a target that stays put, and for a label that shows its points over less than
    SEEN_TRAVEL_SHARE of the target's travel (hidden while it moves: a careful label of
    points the hand covers through the lift shows them only at rest). shown: (F, P) where
    the label shows its points (default: where xy has positions)."""
    if motion.reach < moves_px:
        return None
    where = np.isfinite(xy).all(axis=-1) if shown is None else np.asarray(shown, bool)
    seen = (where[1:] & where[:-1]).any(axis=1)
    travel = np.nan_to_num(motion.step)
    if travel.sum() > 0 and travel[seen].sum() < SEEN_TRAVEL_SHARE * travel.sum():
        return None
    _, reach = track_motion(xy)
    return num(min(reach / motion.reach, 1.0))


def track_jitter(xy: np.ndarray) -> float | None:
    """Root-mean-square second difference of a label's own track (F, P, 2) px, px per frame^2,
    over runs of three frames with positions: no reference needed. A hand or an object moves
    smoothly at 30 fps; random clicks leap by a good part of the image."""
    acc = np.linalg.norm(xy[2:] - 2.0 * xy[1:-1] + xy[:-2], axis=-1)
    return num(np.sqrt(np.nanmean(acc ** 2))) if np.isfinite(acc).any() else None


# The other labels' shake is scaled by how far this track travels against theirs (views see the
# target's motion at different scales: a nearer camera sees it move and turn more), within
# these bounds.
SHAKE_SCALE = (0.25, 3.0)


def expected_shake(xy: np.ndarray, motion: TargetMotion | None) -> float | None:
    """The shake (px per frame^2) the target's own motion gives a track (F, P, 2) px that
    follows it in this view: the other labels' median (TargetMotion.jitter) scaled by this
    track's reach against theirs; None where unknown."""
    if motion is None or motion.jitter is None or motion.reach <= 0.0:
        return None
    _, reach = track_motion(xy)
    return float(motion.jitter * np.clip(reach / motion.reach, *SHAKE_SCALE))
