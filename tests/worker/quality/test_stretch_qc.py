"""QC of interpolated stretches: a track keyed too sparsely through a swing is told, in words,
which stretch it does not follow and is rejected; its contradicted positions vouch for no one;
a track keyed where the path bends passes."""

from __future__ import annotations

import numpy as np

from tests.worker.assist.test_assist_lk import _keys
from tests.worker.assist.test_assist_stretches import COUNT, _truth
from worker.assist.stretches import check_stretches
from worker.hand.joints import JOINT_NAMES
from worker.quality.decide import decide, learn_thresholds
from worker.quality.metrics import AssignmentQC
from worker.quality.stretch_qc import add_stretch_results, without_contradicted
from worker.quality.view_labels import ViewLabels
from worker.synth.annotators import follow_path
from worker.tracks.interpolate import dense_points

CLEAN = {"median_error_px": 2.2, "p90_error_px": 4.0, "outlier_fraction": 0.0,
         "jitter_px": 1.6, "motion_ratio": 1.0, "occluded_on_surface": 0.0,
         "completeness": 1.0, "working_time_s": 120.0, "unfollowed_stretches": 0.0}


def _judged(keyframes: list) -> tuple[AssignmentQC, ViewLabels]:
    frames, _ = _truth(points=len(keyframes))
    check = check_stretches(frames, keyframes)
    xy, visible = dense_points(enumerate(keyframes), COUNT, len(keyframes))
    sent = ViewLabels("7", 0, xy, visible)
    label = without_contradicted(sent, check)
    qc = AssignmentQC("7", 0, dict(CLEAN), [2.0] * len(keyframes), [2.0] * COUNT)
    add_stretch_results({"7": qc}, {"7": check}, {"7": keyframes}, {"7": sent})
    # Contradicted positions are the worker's own work: never "mostly pre-filled".
    assert qc.metrics["decided_fraction"] == 1.0
    return qc, label


def test_sparse_keys_through_a_swing_are_rejected_with_the_stretch_named() -> None:
    _, truth = _truth()
    qc, label = _judged(_keys(truth, [0, 8, 15]))
    assert qc.metrics["unfollowed_stretches"] == 0.5  # 0-8 swings, 8-15 slides straight
    assert label.decided is not None
    assert not label.decided[1:8].any() and label.decided[[0, 8, 9, 15]].all()
    thresholds = learn_thresholds([dict(CLEAN) for _ in range(10)])
    outcome = decide(qc, thresholds, list(JOINT_NAMES))
    assert outcome.outcome == "reject"
    assert any(r.startswith("unfollowed_stretches 0.5 >") for r in outcome.reasons)
    assert "Check these frames: the " in outcome.feedback and " moves 2" in outcome.feedback
    assert "px between frames 0 and 8 that your track does not follow" in outcome.feedback


def test_keys_where_the_path_bends_pass() -> None:
    _, truth = _truth()
    keys = follow_path(truth[:, 0], np.ones(COUNT, bool), [0, 8, 15], tolerance_px=2.0)
    qc, label = _judged(_keys(truth, keys))
    assert qc.metrics["unfollowed_stretches"] == 0.0 and qc.issues == []
    assert label.decided is not None and label.decided.all()
    thresholds = learn_thresholds([dict(CLEAN) for _ in range(10)])
    assert decide(qc, thresholds, list(JOINT_NAMES)).outcome == "approve"


def test_a_track_keyed_on_nearly_every_frame_with_one_stretch_off_is_not_judged_sparse() -> None:
    # As a worker leaves a label after accepting a model follow: points 1-4 keyed on every
    # frame, point 0 on every frame but across the swing (0-8). Its one tracked stretch is
    # contradicted: named in words, but one step of 68, not a track interpolated through
    # motion (as a share of its one tracked stretch it read 1.0, a rejection).
    _, truth = _truth()
    every = list(range(COUNT))
    keys = _keys(truth, every)
    keys[0] = _keys(truth, [0, *range(8, COUNT)])[0]
    qc, label = _judged(keys)
    assert [(i["point"], i["frames"]) for i in qc.issues] == [(0, [0, 8])]
    assert qc.metrics["unfollowed_stretches"] == 1 / 68
    assert label.decided is not None and not label.decided[1:8, 0].any()
    thresholds = learn_thresholds([dict(CLEAN) for _ in range(10)])
    assert decide(qc, thresholds, list(JOINT_NAMES)).outcome == "approve"
