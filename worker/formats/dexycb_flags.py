"""The export's own keys in the DexYCB layout: trust flags and provenance beside the labels.

DexYCB's readers look their keys up by name (``label['pose_y']``, ``meta['ycb_ids']``), so keys
added beside them change nothing for them. What the export adds:

- per camera and frame ``labels_%06d.npz``: ``pose_y_valid`` uint8 (O,), 1 where the object's
  ``pose_y`` row is trusted, 0 where the solve flagged it (the row still holds the solved pose)
  or has no pose (the row is -1). A hand frame that is flagged is unlabelled by DexYCB's own
  rule (``joint_3d``, ``joint_2d`` -1, ``pose_m`` 0): no extra key is needed for it.
- ``pose.npz``: ``pose_y_valid`` uint8 (F, O) as above, ``pose_y_confidence`` float32 (F, O)
  in [0, 1]; ``pose_m_valid`` uint8 (F, H) and ``pose_m_confidence`` float32 (F, H).
- ``meta.yml``: ``label_flags`` = {``pose_y``: {frame: {object position in ``ycb_ids``:
  reason}}, ``hand``: {frame: reason}} with only the flagged entries, and
  ``label_provenance`` = {``hand``: {...}, ``objects``: [{...} per object in ``ycb_ids``
  order]}, each {``views_decided``: F ints, ``views``: {serial: F state words}} (the words of
  :mod:`worker.formats.provenance`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from worker.formats.provenance import views_decided

POSE_Y_VALID = "pose_y_valid"
POSE_Y_CONFIDENCE = "pose_y_confidence"
POSE_M_VALID = "pose_m_valid"
POSE_M_CONFIDENCE = "pose_m_confidence"
META_LABEL_FLAGS = "label_flags"
META_LABEL_PROVENANCE = "label_provenance"


def _checked(flags: np.ndarray, confidence: np.ndarray, ndim: int, what: str
             ) -> tuple[np.ndarray, np.ndarray]:
    flags = np.asarray(flags, dtype=str)
    confidence = np.asarray(confidence, dtype=np.float64)
    if flags.ndim != ndim or confidence.shape != flags.shape:
        raise ValueError(f"{what} flags and confidence must have the same {ndim}-d shape, got "
                         f"{flags.shape} and {confidence.shape}")
    return flags, confidence


def pose_flag_arrays(object_flags: np.ndarray, object_confidence: np.ndarray,
                     object_present: np.ndarray, hand_flags: np.ndarray,
                     hand_confidence: np.ndarray, hand_present: np.ndarray,
                     hands: int) -> dict[str, np.ndarray]:
    """pose.npz's added arrays.

    object_flags, object_confidence, object_present: (O, F) reason ("" = trusted), [0, 1],
    bool (the solve has a pose). hand_flags, hand_confidence, hand_present: (F,); ``hands`` is
    H (0 or 1): the hand arrays come out (F, H).
    """
    object_flags, object_confidence = _checked(object_flags, object_confidence, 2, "object")
    hand_flags, hand_confidence = _checked(hand_flags, hand_confidence, 1, "hand")
    valid = (object_flags == "") & np.asarray(object_present, dtype=bool)
    hand_valid = (hand_flags == "") & np.asarray(hand_present, dtype=bool)
    return {
        POSE_Y_VALID: valid.T.astype(np.uint8),
        POSE_Y_CONFIDENCE: object_confidence.T.astype(np.float32),
        POSE_M_VALID: np.repeat(hand_valid[:, None], hands, axis=1).astype(np.uint8),
        POSE_M_CONFIDENCE: np.repeat(hand_confidence[:, None], hands, axis=1).astype(np.float32),
    }


def frame_flag_arrays(valid: np.ndarray) -> dict[str, np.ndarray]:
    """labels_%06d.npz's added array: ``pose_y_valid`` (O,) uint8 from (O,) bool."""
    return {POSE_Y_VALID: np.asarray(valid, dtype=bool).astype(np.uint8)}


def flags_doc(object_flags: np.ndarray, hand_flags: np.ndarray) -> dict[str, Any]:
    """meta.yml's ``label_flags``: the reason of every flagged object pose and hand frame.

    object_flags: (O, F) str; hand_flags: (F,) str; "" = trusted.
    """
    object_flags = np.asarray(object_flags, dtype=str)
    hand_flags = np.asarray(hand_flags, dtype=str)
    poses: dict[int, dict[int, str]] = {}
    for o, f in zip(*np.nonzero(object_flags != ""), strict=True):
        poses.setdefault(int(f), {})[int(o)] = str(object_flags[o, f])
    hand = {int(f): str(hand_flags[f]) for f in np.flatnonzero(hand_flags != "")}
    return {"pose_y": dict(sorted(poses.items())), "hand": hand}


def provenance_doc(hand: Mapping[str, Any] | None, objects: Sequence[Mapping[str, Any]]
                   ) -> dict[str, Any]:
    """meta.yml's ``label_provenance`` from per target {"views_decided", "views"} entries."""
    return {"hand": None if hand is None else dict(hand), "objects": [dict(o) for o in objects]}


def target_provenance(states: Sequence[Sequence[str]], serials: Sequence[str]
                      ) -> dict[str, Any]:
    """One target's provenance over the clip: {"views_decided": F ints, "views": {serial: F
    state words}} from per view state lists (V lists of F words)."""
    return {"views_decided": views_decided(states),
            "views": {str(s): list(v) for s, v in zip(serials, states, strict=True)}}
