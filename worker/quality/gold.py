"""Scoring one assignment against known labels of the same view (a training clip's gold).

The gold takes the place of the multi-view consensus: the same metrics are measured in the
image, so the same thresholds and decision rules apply. Frames F, points P; image pixels.
"""

from __future__ import annotations

import numpy as np

from worker.quality.metrics import (
    AssignmentQC,
    error_issues,
    error_summary,
    num,
    per_point_and_frame,
    track_metrics,
)
from worker.quality.swaps import find_swaps
from worker.quality.view_labels import ViewLabels

# Same meaning as the consensus' outlier threshold: five times a careful annotator's 2 px.
GOLD_OUTLIER_PX = 10.0


def score_against_gold(label: ViewLabels, gold_xy: np.ndarray, gold_visible: np.ndarray,
                       outlier_px: float = GOLD_OUTLIER_PX) -> AssignmentQC:
    """Quality of ``label`` measured against the gold of its view.

    Args:
        label: the worker's labels, xy (F, P, 2) px (NaN = no position), visible (F, P).
        gold_xy: (F, P, 2) px known positions (NaN = none). gold_visible: (F, P) bool.

    Returns:
        AssignmentQC with the consensus metrics' names; errors are measured where both the
        worker and the gold mark the point visible; visibility disagreement counts frames where
        the flags differ.
    """
    xy = np.asarray(label.xy, dtype=np.float64)
    visible = np.asarray(label.visible, dtype=bool)
    gold_xy = np.asarray(gold_xy, dtype=np.float64)
    gold_visible = np.asarray(gold_visible, dtype=bool)
    if gold_xy.shape != xy.shape or gold_visible.shape != visible.shape:
        raise ValueError(f"gold must match the label: xy {xy.shape} and visible "
                         f"{visible.shape}, got {gold_xy.shape} and {gold_visible.shape}")
    both = visible & gold_visible
    errors = np.where(both, np.linalg.norm(xy - gold_xy, axis=-1), np.nan)
    scored = np.isfinite(errors)
    metrics = error_summary(errors)
    metrics["outlier_fraction"] = num((errors[scored] > outlier_px).mean()) if scored.any() \
        else None
    metrics["visibility_disagreement"] = num((visible != gold_visible).mean())
    metrics["occluded_on_surface"] = (num((~visible & gold_visible).sum() / gold_visible.sum())
                                      if gold_visible.any() else None)
    metrics["visible_behind_surface"] = (num((visible & ~gold_visible).sum()
                                             / (~gold_visible).sum())
                                         if (~gold_visible).any() else None)
    metrics.update(track_metrics(xy, visible, gold_xy, label.working_time_s))
    metrics["scored_fraction"] = num(scored.mean())
    per_joint, per_frame = per_point_and_frame(errors)
    swaps = find_swaps(xy, visible, gold_xy) if xy.shape[1] == 21 else []
    return AssignmentQC(key=label.key, view=label.view, metrics=metrics, per_joint=per_joint,
                        per_frame=per_frame, swaps=swaps,
                        issues=error_issues(errors, outlier_px), provisional=False)
