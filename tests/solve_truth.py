"""A finished solve run whose outputs are a synthetic capture's ground truth, without the solver.

The hand is the capture's own pose_m (world frame) posed with the sequence's betas; objects are
their true poses. Per-frame reprojection errors follow a fixed pattern that grows with the
frame (frame f: joint j in view v errs 0.5 + f + 0.25 j + v px), so a chart of them differs
from frame to frame. Chosen frames can be flagged: object 0 untrusted there, with a reason.
Used by the API and browser tests of solve review (compare, overlays, flagged frames).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from sqlalchemy import select

from backend.captures.assets import hand_model_for
from backend.captures.models import Hand
from backend.captures.service import get_sequence_or_raise
from backend.db import session_scope
from backend.solve.service import store_result
from worker.formats import dexycb
from worker.geometry.transforms import quaternion_to_matrix
from worker.hand import HandLayer
from worker.solver.types import SolveResult

FLAG_REASON = "landmarks 14.0 px off in 2 views"
FLAG_CONFIDENCE = 0.2


def true_poses(capture: Path) -> tuple[np.ndarray, np.ndarray]:
    """The capture's (first) sequence: pose_m (F, 51) and object poses (O, F, 3, 4), world."""
    seq_dir = min(p.parent for p in Path(capture).glob(f"*/*/{dexycb.META_FILE}"))
    with np.load(seq_dir / dexycb.POSE_FILE) as npz:
        pose_y = npz[dexycb.POSE_Y].astype(np.float64)  # (F, O, 7) xyzw + t
        pose_m = npz[dexycb.POSE_M].astype(np.float64)[:, 0]
    rot = quaternion_to_matrix(pose_y[..., :4])
    poses = np.concatenate([rot, pose_y[..., 4:, None]], axis=-1)
    return pose_m, np.swapaxes(poses, 0, 1)


def truth_result(capture: Path, betas: Sequence[float], views: int,
                 flagged: Sequence[int] = (), hand_shift_m: Sequence[float] = (0, 0, 0),
                 object_turn_deg: float = 0.0) -> SolveResult:
    """The capture's truth as a SolveResult; ``hand_shift_m`` moves the hand (world metres) and
    ``object_turn_deg`` turns object 0 about its own z axis in every frame (a second run that
    differs by a known amount)."""
    pose_m, object_poses = true_poses(capture)
    pose_m = pose_m.copy()
    pose_m[:, 48:51] += np.asarray(hand_shift_m, dtype=np.float64)
    if object_turn_deg:
        t = np.radians(object_turn_deg)
        turn = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1.0]])
        object_poses = object_poses.copy()
        object_poses[0, :, :, :3] = object_poses[0, :, :, :3] @ turn
    frames, objects = len(pose_m), object_poses.shape[0]
    layer = HandLayer(hand_model_for("right"))
    with torch.no_grad():
        joints = layer.from_pose_m(torch.as_tensor(pose_m),
                                   torch.as_tensor(np.asarray(betas, dtype=np.float64))).joints
    f, v, j = np.meshgrid(np.arange(frames), np.arange(views), np.arange(21), indexing="ij")
    confidence = np.ones((objects, frames))
    flags: list[list[str | None]] = [[None] * frames for _ in range(objects)]
    for frame in flagged:
        confidence[0, frame] = FLAG_CONFIDENCE
        flags[0][frame] = FLAG_REASON
    return SolveResult(
        hand_pose_m=pose_m, hand_joints=joints.numpy().astype(np.float64),
        object_poses=object_poses, labelled=np.ones(frames, bool), reasons=[None] * frames,
        kpt_error_px=(0.5 + f + 0.25 * j + v).astype(np.float64),
        depth_rms_mm=np.full(frames, 1.0), landmark_vertices=[[] for _ in range(objects)],
        timings={}, betas=np.asarray(betas, dtype=np.float64), object_confidence=confidence,
        object_flags=flags)


def store_truth_run(capture: Path, sequence_id: int, **changes: object) -> int:
    """Store a done run of ``sequence_id`` holding truth_result(capture, ...); its id."""
    with session_scope() as session:
        hand = session.scalars(select(Hand).where(Hand.sequence_id == sequence_id)).one()
        betas = list(hand.betas or [])
        views = len(get_sequence_or_raise(session, sequence_id).cameras)
        result = truth_result(capture, betas, views, **changes)  # type: ignore[arg-type]
        return store_result(session, sequence_id, result, hand.side).id
