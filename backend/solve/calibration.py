"""calibrate-hand: the subject's MANO betas from the sequence's accepted hand tracks.

Every labelled-visible joint is triangulated per frame from all views; the per-bone median of
the bone lengths over frames is matched by the model's rest-pose bone lengths
(worker.hand.calibrate). Occluded labels are guesses and are left out of the triangulation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sqlalchemy.orm import Session

from backend.captures.assets import hand_model_for
from backend.captures.service import camera_model, get_sequence_or_raise, sequence_cameras
from backend.errors import Conflict, NotFound
from backend.labels import approved_labels
from backend.solve.inputs import hand_target
from backend.solve.service import SolveNotReady
from worker.hand.calibrate import (
    LABELLED_RIDGE,
    fit_betas,
    median_bone_lengths,
    triangulate_joints,
)

# Bones measured in fewer frames than this give no trustworthy median.
MIN_FRAMES = 3


@dataclass
class Calibration:
    """What calibrate-hand stored: betas (10,), bone-length residuals (mm), frames used."""

    hand_index: int
    side: str
    betas: list[float]
    max_residual_mm: float
    frames_used: int


def calibrate_hand(session: Session, sequence_id: int, *, force: bool = False,
                   hand_index: int = 0) -> Calibration:
    """Fit and store hand ``hand_index``'s betas; refuses to replace existing ones unless
    ``force``. Raises NotFound, Conflict (betas exist) or SolveNotReady (too few labels)."""
    seq = get_sequence_or_raise(session, sequence_id)
    hand = next((h for h in seq.hands if h.index == hand_index), None)
    if hand is None:
        raise NotFound(f"sequence {sequence_id} has no hand {hand_index}")
    if hand.betas and not force:
        source = f"the calibration file mano_{hand.calib_name}" if hand.calib_name else "before"
        raise Conflict(f"hand {hand_index} already has betas (from {source}); pass --force to "
                       "overwrite them")
    cameras = sequence_cameras(session, sequence_id)
    labels = approved_labels(session, sequence_id, seq.num_frames)
    target = hand_target(seq, cameras, labels, hand_index)
    if target is None:  # for the type checker: the hand was found above
        raise NotFound(f"sequence {sequence_id} has no hand {hand_index}")
    joints = triangulate_joints([camera_model(c) for c in cameras], target.keypoints,
                                 target.visible)
    try:
        lengths = median_bone_lengths(joints, min_frames=MIN_FRAMES)
    except ValueError as exc:
        raise SolveNotReady(f"cannot calibrate hand {hand_index} of sequence {sequence_id} "
                            f"from its accepted tracks: {exc}") from None
    fit = fit_betas(lengths, hand_model_for(hand.side), ridge=LABELLED_RIDGE)
    hand.betas = [float(b) for b in fit.betas]
    session.flush()
    used = int(np.isfinite(joints).all(axis=(1, 2)).sum())
    return Calibration(hand_index=hand_index, side=hand.side, betas=hand.betas,
                       max_residual_mm=float(np.abs(fit.residual_mm).max()), frames_used=used)
