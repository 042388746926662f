"""QC of interpolated stretches: what the view's images say about a worker's straight lines.

Each hand label's stretches between keyframes are checked against its own view's images
(worker.assist.stretches). Two things follow:

- positions the images contradict (interpolated where the point moved away from the line) are
  not the worker's decision on that frame: they enter no consensus and are scored by no one
  (ViewLabels.decided False there), so several workers who interpolated the same frames never
  vouch for each other where the images say the point moved;
- ``decided_fraction`` keeps meaning what the worker took from pre-filled suggestions
  (decide.py's "mostly pre-filled" rule): it is measured on the label as sent, not on the
  positions the images took away;
- a label whose own evidence fails it at the reject level (the images contradict most of its
  stretches, or its track leaps like random clicks) judges no one: it enters no consensus and
  witnesses no motion (``discredited``), so work checked against other views is never judged
  by references the images already refuse;
- the share of the label's tracked stretches the images contradict is a metric
  (``unfollowed_stretches``, judged in worker.quality.decide) and each such stretch an issue
  in words ("ring tip moves 14 px between frames 4 and 8 that the track does not follow").

Pure: arrays in, arrays out.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from worker.assist.lk import tracked_spans
from worker.assist.stretches import StretchCheck
from worker.quality.bounds import METRIC_BOUNDS
from worker.quality.metrics import AssignmentQC
from worker.quality.motion import track_jitter
from worker.quality.view_labels import ViewLabels


def without_contradicted(label: ViewLabels, check: StretchCheck) -> ViewLabels:
    """The label with ``decided`` False where the images contradict its interpolation."""
    decided = np.ones(label.visible.shape, bool) if label.decided is None else label.decided
    frames, points = label.visible.shape
    contradicted = np.zeros((frames, points), bool)
    rows, cols = check.contradicted.shape
    contradicted[:min(rows, frames), :min(cols, points)] = \
        check.contradicted[:frames, :points]
    return dataclasses.replace(label, decided=decided & ~contradicted)


def stretch_issues(check: StretchCheck) -> list[dict[str, Any]]:
    """The check's issues as QC issue dicts ({"point", "frames", "frame", "error_px",
    "about": "stretch"}), worst first."""
    return [issue.to_dict() for issue in check.issues]


def unfollowed_share(check: StretchCheck, keyframes: Sequence[Sequence[Any]]) -> float | None:
    """Share of the label's steps from one visible keyframe of a point to its next that the
    images say the track does not follow; None when it has no tracked stretch
    (worker.assist.lk.tracked_spans). A step to the next frame follows by construction (the
    worker placed or accepted both ends) and counts as followed: a label keyed on nearly every
    frame (a model follow accepted) with one stretch of three contradicted is not a track
    interpolated through motion (a third, reviewed, on s5151's start view, 1,499 keyframes at
    0.59 px median from the other views)."""
    steps = tracked_spans(keyframes, 0, check.evidence.shape[0], min_gap=1)
    if not any(k1 - k0 >= 2 for _, k0, k1, _, _ in steps):
        return None
    return len(check.issues) / len(steps)


def decided_fraction(label: ViewLabels) -> float | None:
    """Share of the label's shown positions (visible, placed) that are the worker's own
    decision by provenance (ViewLabels.decided as sent); None when it shows none."""
    sent = np.asarray(label.visible, bool) & np.isfinite(label.xy).all(axis=-1)
    decided = sent if label.decided is None else sent & np.asarray(label.decided, bool)
    return float(decided.sum() / sent.sum()) if sent.any() else None


def add_stretch_results(results: Mapping[str, AssignmentQC], checks: Mapping[str, StretchCheck],
                        keyframes: Mapping[str, Sequence[Sequence[Any]]],
                        sent: Mapping[str, ViewLabels]) -> None:
    """Write each checked label's ``unfollowed_stretches`` metric, its stretch issues (first)
    and its decided_fraction as sent (``sent``: the labels before `without_contradicted`)
    into its QC result, in place."""
    for key, qc in results.items():
        check = checks.get(key)
        if check is None:
            continue
        qc.metrics["unfollowed_stretches"] = unfollowed_share(check, keyframes[key])
        if key in sent:
            qc.metrics["decided_fraction"] = decided_fraction(sent[key])
        qc.issues[:0] = stretch_issues(check)


def _reject_floor(metric: str) -> float:
    bound = METRIC_BOUNDS[metric].reject
    assert bound is not None
    return bound[0]


def discredited(labels: Sequence[ViewLabels], checks: Mapping[str, StretchCheck],
                keyframes: Mapping[str, Sequence[Sequence[Any]]]) -> frozenset[str]:
    """Keys of the labels whose own evidence, read without any other view, fails them at the
    lowest reject threshold: the images contradict that share of their tracked stretches
    (``unfollowed_stretches``), or their shown track leaps as random clicks do
    (``track_jitter_px``). Careful work stays far below both (bounds.py)."""
    out = set()
    for lab in labels:
        check = checks.get(lab.key)
        share = unfollowed_share(check, keyframes[lab.key]) if check is not None else None
        shown = np.where(np.asarray(lab.visible, bool)[..., None],
                         np.asarray(lab.xy, np.float64), np.nan)
        shake = track_jitter(shown)
        if (share is not None and share >= _reject_floor("unfollowed_stretches")) or \
                (shake is not None and shake >= _reject_floor("track_jitter_px")):
            out.add(lab.key)
    return frozenset(out)
