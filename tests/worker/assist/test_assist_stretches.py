"""Interpolated stretches checked against the view's images: a textured scene with a known
motion, tracks keyed too sparsely for it (the line leaves the path) and keyed where it bends."""

from __future__ import annotations

import numpy as np

from tests.worker.assist.test_assist_lk import _frames, _keys
from worker.assist.stretches import (
    EVIDENCE_CONFIRMED,
    EVIDENCE_CONTRADICTED,
    EVIDENCE_KEYED,
    check_stretches,
)
from worker.synth.annotators import follow_path

COUNT = 16


def _swing() -> np.ndarray:
    """(F, 2) px: the scene swings 24 px down and back over frames 0-8, then slides right."""
    t = np.arange(COUNT, dtype=np.float64)
    y = np.where(t <= 8, 24.0 * np.sin(np.pi * t / 8), 0.0)
    x = np.where(t <= 8, 0.0, 3.0 * (t - 8))
    return np.stack([x, y], axis=1)


def _truth(points: int = 5) -> tuple[np.ndarray, np.ndarray]:
    shift = _swing()
    start = np.random.default_rng(2).uniform([60, 60], [260, 150], (points, 2))
    return _frames(shift, seed=3), start[None] + shift[:, None]


def test_sparse_keys_over_a_swing_are_issues_in_words() -> None:
    frames, truth = _truth()
    check = check_stretches(frames, _keys(truth, [0, 8, 15]))
    # Every point's stretch 0-8 swings 24 px off the line; 8-15 is a straight slide.
    assert sorted((i.point, i.first, i.last) for i in check.issues) == \
        [(p, 0, 8) for p in range(5)]
    assert all(20.0 < i.offset_px < 28.0 and 3 <= i.frame <= 5 for i in check.issues)
    assert check.issues[0].sentence("ring tip").startswith("ring tip moves 2")
    assert check.issues[0].sentence("ring tip").endswith(
        "px between frames 0 and 8 that the track does not follow")
    assert (check.evidence[1:8] == EVIDENCE_CONTRADICTED).all()
    assert (check.evidence[9:15] == EVIDENCE_CONFIRMED).all()
    assert (check.evidence[[0, 8, 15]] == EVIDENCE_KEYED).all()


def test_keys_where_the_path_bends_leave_no_issue() -> None:
    frames, truth = _truth()
    keys = follow_path(truth[:, 0], np.ones(COUNT, bool), [0, 8, 15], tolerance_px=2.0)
    check = check_stretches(frames, _keys(truth, keys))
    assert check.issues == []
    assert not check.contradicted.any()
    inner = np.setdiff1d(np.arange(COUNT), keys)
    assert (check.evidence[inner] == EVIDENCE_CONFIRMED).mean() > 0.9
