"""The solved hand's per-frame confidence: frames no two views decided are flagged with the
reason; keyed or image-confirmed views decide; residuals far off flag too."""

from __future__ import annotations

import numpy as np

from worker.assist.stretches import (
    EVIDENCE_CONFIRMED,
    EVIDENCE_KEYED,
    EVIDENCE_UNCHECKED,
)
from worker.solver.hand_confidence import hand_confidence

VIEWS, FRAMES, JOINTS = 4, 6, 21


def _judge(codes: np.ndarray, kpt_px: float = 2.0, labelled: np.ndarray | None = None):
    visible = np.ones((VIEWS, FRAMES, JOINTS), bool)
    labelled = np.ones(FRAMES, bool) if labelled is None else labelled
    errors = np.full((FRAMES, VIEWS, JOINTS), kpt_px)
    return hand_confidence(codes, visible, labelled, [None] * FRAMES, errors,
                           np.full(FRAMES, 6.0))


def test_frames_only_interpolated_in_all_but_one_view_are_flagged() -> None:
    codes = np.full((VIEWS, FRAMES, JOINTS), EVIDENCE_KEYED, np.int8)
    codes[1:, 2] = EVIDENCE_UNCHECKED          # frame 2: one view keyed, three interpolate
    codes[:, 4] = EVIDENCE_UNCHECKED           # frame 4: every view interpolates
    codes[2:, 4] = EVIDENCE_CONFIRMED          # ... but two views' images confirm it
    confidence, flags = _judge(codes)
    assert [f is None for f in flags] == [True, True, False, True, True, True]
    assert flags[2] == ("hand decided by 1 view from keyframes or tracking; 3 views only "
                        "interpolate there without support from the images")
    assert confidence[2] < 0.5 and confidence[0] == 1.0 and 0.6 < confidence[4] < 0.7


def test_labels_without_provenance_are_trusted_and_residuals_still_flag() -> None:
    confidence, flags = _judge(None, kpt_px=2.0)
    assert flags == [None] * FRAMES and (confidence == 1.0).all()
    _, flags = _judge(None, kpt_px=14.0)
    assert flags[0] == "hand joints reproject 14 px from the labels"
    labelled = np.ones(FRAMES, bool)
    labelled[5] = False
    _, flags = _judge(None, labelled=labelled)
    assert flags[5] == "hand not solved on this frame"
