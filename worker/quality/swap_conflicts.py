"""Swapped fingers against the consensus: where labels accuse each other of the same swap, the
explanation that makes the views agree best; the suspected swappers' votes cut; a label with its
swaps undone for the refit.
"""

from __future__ import annotations

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.geometry.refine import CameraStack, reprojection_errors
from worker.quality.consensus_fit import Fit, HandOptions, fit_consensus
from worker.quality.hand_report import HandReport
from worker.quality.swaps import consensus_swapped, moved_joints, overlaps, undo_swaps
from worker.quality.view_labels import ViewLabels, decided_of


def _own_swaps(report: HandReport, corrections: dict[str, list[dict]]) -> list[tuple[str, dict]]:
    """(label key, swap) of every correction that undoes the label's own detected swap (not
    one the consensus made)."""
    return [(key, s) for key, found in corrections.items() for s in found
            if any(overlaps(s, t) for t in report.assignments[key].swaps)]


def _conflicts(items: list[tuple[str, dict]]) -> list[list[tuple[str, dict]]]:
    """Groups of swaps of the same fingers over overlapping frames from different labels."""
    groups: list[list[tuple[str, dict]]] = []
    for item in items:
        joined = [g for g in groups if any(overlaps(item[1], other) for _, other in g)]
        merged = [item] + [x for g in joined for x in g]
        groups = [g for g in groups if g not in joined] + [merged]
    return [g for g in groups if len({key for key, _ in g}) > 1]


def resolve_conflicts(cameras: list[CameraModel], labels: list[ViewLabels],
                       corrections: dict[str, list[dict]], report: HandReport, fit: Fit,
                       opts: HandOptions) -> dict[str, list[dict]]:
    """Where labels accuse each other of the same swap over overlapping frames, keep the
    explanation that makes the views agree best.

    With few views a careful label's reference may be made from a swapper and one other view;
    it then looks swapped too; where the swappers outnumber them, careful labels are the
    accused. Each accused label alone, all of them together (several swappers), and every
    other label instead (the accused were right) are undone in turn; the consensus of the
    affected points is refitted, and the choice with the least robust reprojection cost over
    every label wins, among those whose palm is not exchanged over the span
    (consensus_swapped) where there are any.
    """
    groups = _conflicts(_own_swaps(report, corrections))
    if not groups:
        return corrections
    for group in groups:
        rows = np.zeros(report.consensus.shape[:2], bool)
        frames = [min(s["frames"][0] for _, s in group), max(s["frames"][1] for _, s in group)]
        rows[frames[0]:frames[1] + 1, moved_joints([s for _, s in group])] = True
        flat = np.flatnonzero(rows.ravel())
        span = {"kind": group[0][1]["kind"], "fingers": group[0][1]["fingers"],
                "frames": frames}
        accused = {key for key, _ in group}
        # Each accused label alone, all of them, or none of them but everyone else (the
        # consensus was the swappers' and the accused were right).
        choices = [_trial(corrections, group, [item]) for item in group]
        choices.append(_trial(corrections, group, group))
        flipped = _trial(corrections, group, [])
        choices.append({key: found + ([] if key in accused or any(overlaps(span, t)
                                                                    for t in found) else [span])
                        for key, found in flipped.items()})
        costs = []
        for trial in choices:
            trial_labels = [undone(lab, trial[lab.key]) for lab in labels]
            trial_fit = fit_consensus(cameras, trial_labels, opts, fit, also=rows.ravel())
            # An explanation that leaves the palm exchanged over the span is the swappers'
            # (two against two ties on the reprojection cost alone).
            palm = consensus_swapped(trial_fit.points.reshape(report.consensus.shape), span)
            costs.append((palm, _robust_cost(cameras, labels, trial_fit, flat, opts.outlier_px)))
        corrections = choices[min(range(len(choices)), key=lambda i: costs[i])]
    return corrections


def _trial(corrections: dict[str, list[dict]], group: list[tuple[str, dict]],
           chosen: list[tuple[str, dict]]) -> dict[str, list[dict]]:
    """``corrections`` with, of the conflicting ``group``, only the ``chosen`` swaps undone."""
    return {key: [s for s in found if (key, s) not in group or (key, s) in chosen]
            for key, found in corrections.items()}


def _robust_cost(cameras: list[CameraModel], labels: list[ViewLabels], fit: Fit,
                 rows: np.ndarray, cap_px: float) -> float:
    """Sum over the rows' observations of min(error, cap)^2 px^2, each label against the
    fitted points as it entered the fit."""
    stack = CameraStack.of([cameras[lab.view] for lab in labels])
    errors = reprojection_errors(stack, fit.pixels[rows], fit.points[rows])
    capped = np.minimum(np.where(np.isfinite(errors), errors, 0.0), cap_px)
    observed = np.isfinite(fit.pixels[rows]).all(axis=-1)
    # A point the trial could not fit at all costs every observation the cap.
    capped = np.where(np.isfinite(fit.points[rows]).all(axis=1)[:, None], capped, cap_px)
    return float((np.where(observed, capped, 0.0) ** 2).sum())


def suspects(report: HandReport, labels: list[ViewLabels], corrections: dict[str, list[dict]],
              fit: Fit, opts: HandOptions) -> tuple[np.ndarray, np.ndarray]:
    """Label reliabilities (L,) with the detected swappers' votes (and weights) cut, and the
    rows (N,) bool
    to solve again: every frame of the joints their swaps move. Where a swapper and one
    careful view are the only two views of a point left, the two hypotheses tie; a swap
    found elsewhere in the clip is what breaks the tie, beyond the span already undone."""
    reliability = fit.reliability.copy()
    swaps: list[dict] = []
    for col, lab in enumerate(labels):
        own = [s for s in corrections[lab.key]
               if any(overlaps(s, t) for t in report.assignments[lab.key].swaps)]
        if own:
            reliability[col] *= opts.suspect_vote
            swaps += own
    rows = np.zeros(report.consensus.shape[:2], bool)
    if swaps:
        rows[:, moved_joints(swaps)] = True
    return reliability, rows.ravel()


def undone(lab: ViewLabels, swaps: list[dict]) -> ViewLabels:
    if not swaps:
        return lab
    sent_xy = np.asarray(lab.xy, np.float64)
    xy, visible = undo_swaps(sent_xy, np.asarray(lab.visible, bool), swaps)
    # The decisions move with the points they belong to.
    decided = None if lab.decided is None else undo_swaps(sent_xy, decided_of(lab), swaps)[1]
    return ViewLabels(lab.key, lab.view, xy, visible, lab.working_time_s, decided)
