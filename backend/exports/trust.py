"""The trust and provenance fields that travel beside exported labels, and the joints that lie
outside a view's image.

The solve keeps every value and says how far to trust it (backend.solve.results: object_trust,
hand_trust); the formats write these fields in the forms their readers expect (README, Export).
Pixels x right, y down, in the stored (raw) image of a view; world metres.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from backend.exports.content import SequenceContent, ViewContent
from worker.formats.provenance import deciding_views, frame_actions, views_decided


def object_fields(content: SequenceContent, index: int, frame: int) -> dict[str, Any]:
    """An object pose's trust and provenance at ``frame``: pose_valid (bool), pose_confidence
    in [0, 1], pose_flag (the reason, or None) and provenance ({views_decided, views})."""
    solve = content.solve
    assert solve is not None
    trust = solve.object_flag(index, frame)
    return {"pose_valid": trust["valid"], "pose_confidence": trust["confidence"],
            "pose_flag": trust["flag"],
            "provenance": content.provenance(f"object:{index}", frame)}


def hand_fields(content: SequenceContent, frame: int) -> dict[str, Any]:
    """The hand's trust and provenance at ``frame``: hand_valid (the solve labelled the frame and
    did not flag it), hand_confidence, hand_flag (reason or None) and provenance. Without a
    solve only the provenance."""
    key = f"hand:{content.hands[0].index}"
    out: dict[str, Any] = {"provenance": content.provenance(key, frame)}
    solve = content.solve
    if solve is not None:
        flag = str(solve.hand_flags[frame])
        out.update(hand_valid=solve.hand_trusted(frame),
                   hand_confidence=round(float(solve.hand_confidence[frame]), 3),
                   hand_flag=flag or None)
    return out


def target_decisions(content: SequenceContent, target_key: str) -> dict[str, Any]:
    """One target's provenance over the clip as the JSON export writes it: per frame
    views_decided (a count), deciding_views (the serials whose own keyframes decided it) and
    actions (the accepted work's human actions attributable to the frame, shared out by
    worker.formats.provenance.frame_actions), with each view's states."""
    states = content.provenance_states(target_key)
    serials = [v.serial for v in content.views]
    accepted = [(w.edit_count, w.keyframes) for w in content.work
                if w.target_key == target_key and w.status == "approved"]
    actions = frame_actions(accepted, content.num_frames)
    return {"views_decided": views_decided(states),
            "deciding_views": deciding_views(states, serials),
            "actions": [round(float(a), 2) for a in actions],
            "views": {str(s): list(v) for s, v in zip(serials, states, strict=True)}}


def outside_joints(content: SequenceContent, view: ViewContent, frame: int) -> np.ndarray:
    """(21,) bool: the solved joint projects outside ``view``'s stored image (or behind the
    camera) at ``frame``; all False where the solve has no hand there. The image covers
    [-0.5, W - 0.5) x [-0.5, H - 0.5) with pixel centres at integers."""
    solve = content.solve
    if solve is None or not content.hands:
        return np.zeros(21, dtype=bool)
    joints = np.asarray(solve.arrays["hand_joints"][frame], dtype=np.float64)
    if not np.isfinite(joints).all():
        return np.zeros(len(joints), dtype=bool)
    cam = view.camera
    R, t = cam.T_cam_to_world[:, :3], cam.T_cam_to_world[:, 3]
    depth = (joints - t) @ R[:, 2]
    xy = cam.project(joints)
    with np.errstate(invalid="ignore"):
        inside = ((xy >= -0.5).all(axis=1) & (xy[:, 0] < cam.width - 0.5)
                  & (xy[:, 1] < cam.height - 0.5) & (depth > 0))
    return np.asarray(~inside, dtype=bool)


def outside_tracks(content: SequenceContent, view: ViewContent) -> np.ndarray:
    """(F, 21) bool: :func:`outside_joints` at every frame."""
    return np.stack([outside_joints(content, view, f) for f in range(content.num_frames)]) \
        if content.num_frames else np.zeros((0, 21), dtype=bool)
