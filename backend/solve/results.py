"""A run's per-frame outputs as one npz in storage, and the summary kept on the run's row.

Arrays (F frames, V views, O objects, world frame, metres unless named):
    hand_pose_m (F, 51) DexYCB pose_m, NaN rows where unlabelled; hand_joints (F, 21, 3);
    object_poses (O, F, 3, 4) object-to-world; labelled (F,) bool; reasons (F,) str ("" = none);
    kpt_error_px (F, V, 21) NaN where unobserved; depth_rms_mm (F,);
    landmark_vertices (L, 2) int rows [object, vertex] in landmark order; betas (K,);
    hand_side () str; serials (V,) str; object_names (O,) str;
    object_confidence (O, F) in [0, 1]; object_flags (O, F) str, why a pose is not trusted
    ("" = trusted); hand_confidence (F,) in [0, 1]; hand_flags (F,) str, why a hand frame is
    not trusted ("" = trusted). Exports keep a flagged object pose beside its flag and leave a
    flagged hand frame unlabelled. Results stored before these arrays existed read as fully
    trusted (see `object_trust`, `hand_trust`).
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from worker.hand.joints import FINGER_NAMES, JOINT_NAMES, TIP_NAMES

TIP_INDICES = [JOINT_NAMES.index(name) for name in TIP_NAMES]


def result_key(storage_uid: str, run_id: int) -> str:
    return f"solves/{storage_uid}/run_{run_id:06d}/result.npz"


def encode_result(result: Any, serials: list[str], object_names: list[str],
                  hand_side: str | None) -> bytes:
    """The npz bytes of a worker.solver SolveResult with the names the API shows."""
    rows = [[o, v] for o, ids in enumerate(result.landmark_vertices) for v in ids]
    betas = result.betas if getattr(result, "betas", None) is not None else np.zeros(0)
    arrays = {
        "hand_pose_m": np.asarray(result.hand_pose_m, dtype=np.float64),
        "hand_joints": np.asarray(result.hand_joints, dtype=np.float64),
        "object_poses": np.asarray(result.object_poses, dtype=np.float64),
        "labelled": np.asarray(result.labelled, dtype=bool),
        "reasons": np.asarray([r or "" for r in result.reasons], dtype=str),
        "kpt_error_px": np.asarray(result.kpt_error_px, dtype=np.float64),
        "depth_rms_mm": np.asarray(result.depth_rms_mm, dtype=np.float64),
        "landmark_vertices": np.asarray(rows, dtype=np.int64).reshape(-1, 2),
        "betas": np.asarray(betas, dtype=np.float64),
        "hand_side": np.asarray(hand_side or ""),
        "serials": np.asarray(serials, dtype=str),
        "object_names": np.asarray(object_names, dtype=str),
        "object_confidence": np.asarray(result.object_confidence, dtype=np.float64).reshape(
            len(object_names), len(result.labelled)),
        "object_flags": np.asarray([[r or "" for r in flags] for flags in result.object_flags],
                                   dtype=str).reshape(len(object_names), len(result.labelled)),
        **_hand_arrays(result, len(result.labelled)),
    }
    buf = io.BytesIO()
    # The keys are the arrays' names above; none of them is savez's allow_pickle keyword.
    np.savez_compressed(buf, **arrays)  # type: ignore[arg-type]
    return buf.getvalue()


def _hand_arrays(result: Any, frames: int) -> dict[str, np.ndarray]:
    """hand_confidence (F,) and hand_flags (F,) of a result; a result without them (no hand,
    or made before they existed) is trusted where labelled."""
    confidence = np.asarray(getattr(result, "hand_confidence", np.zeros(0)), np.float64)
    flags = list(getattr(result, "hand_flags", []) or [])
    if confidence.shape != (frames,) or len(flags) != frames:
        labelled = np.asarray(result.labelled, bool)
        confidence = labelled.astype(np.float64)
        flags = [None if ok else "hand not solved on this frame" for ok in labelled]
    return {"hand_confidence": confidence,
            "hand_flags": np.asarray([r or "" for r in flags], dtype=str).reshape(frames)}


def decode_result(data: bytes) -> dict[str, np.ndarray]:
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        return {name: npz[name] for name in npz.files}


def object_trust(arrays: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(O, F) confidence and (O, F) flag reasons ("" = trusted) of a result's object poses."""
    count, frames = arrays["object_poses"].shape[:2]
    confidence = arrays.get("object_confidence")
    flags = arrays.get("object_flags")
    if confidence is None or confidence.shape != (count, frames):
        confidence = np.ones((count, frames))
    if flags is None or flags.shape != (count, frames):
        flags = np.full((count, frames), "", dtype=str)
    return confidence, flags


def hand_trust(arrays: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(F,) confidence in [0, 1] and (F,) flag reasons ("" = trusted) of a result's hand frames.

    Results without ``hand_confidence`` / ``hand_flags`` (or with arrays of another length) read
    as fully trusted: confidence 1, no flag.
    """
    frames = len(arrays["labelled"])
    confidence = arrays.get("hand_confidence")
    flags = arrays.get("hand_flags")
    if confidence is None or confidence.shape != (frames,):
        confidence = np.ones(frames)
    if flags is None or flags.shape != (frames,):
        flags = np.full(frames, "", dtype=str)
    return np.asarray(confidence, dtype=np.float64), np.asarray(flags, dtype=str)


def _mean_or_none(values: np.ndarray) -> float | None:
    values = values[np.isfinite(values)]
    return round(float(values.mean()), 4) if values.size else None


def residual_summary(kpt_error_px: np.ndarray, depth_rms_mm: np.ndarray,
                     labelled: np.ndarray) -> dict[str, Any]:
    """What stands in for accuracy on real data (no ground truth there).

    fingertip_px: mean reprojection error (px) of each fingertip over labelled frames and the
    views that observe it; kpt_px_mean / kpt_px_median over all joints; depth_rms_mm: mean of
    the per-frame RMS point-to-mesh distances (mm); labelled_frames of frames.
    """
    labelled = np.asarray(labelled, dtype=bool)
    errors = np.asarray(kpt_error_px, dtype=np.float64)[labelled]
    tips = {finger: _mean_or_none(errors[:, :, j])
            for finger, j in zip(FINGER_NAMES, TIP_INDICES, strict=True)}
    finite = errors[np.isfinite(errors)]
    return {
        "fingertip_px": tips,
        "kpt_px_mean": _mean_or_none(finite),
        "kpt_px_median": round(float(np.median(finite)), 4) if finite.size else None,
        "depth_rms_mm": _mean_or_none(np.asarray(depth_rms_mm, dtype=np.float64)),
        "labelled_frames": int(labelled.sum()),
        "frames": int(labelled.size),
    }


def _finite_or_none(values: np.ndarray) -> Any:
    """A float array as nested lists with None where it is not finite (JSON has no NaN)."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 0:
        return float(values) if np.isfinite(values) else None
    return [_finite_or_none(v) for v in values]


def frame_payload(arrays: dict[str, np.ndarray], frame: int) -> dict[str, Any]:
    """One frame's outputs as JSON-ready values (None for NaN)."""
    labelled = bool(arrays["labelled"][frame])
    serials = [str(s) for s in arrays["serials"]]
    errors = arrays["kpt_error_px"][frame]
    pose_m = arrays["hand_pose_m"][frame]
    confidence, flags = object_trust(arrays)
    hand_confidence, hand_flags = hand_trust(arrays)
    return {
        "frame": frame,
        "labelled": labelled,
        "reason": str(arrays["reasons"][frame]) or None,
        "hand_confidence": round(float(hand_confidence[frame]), 3),
        "hand_flag": str(hand_flags[frame]) or None,
        "hand_pose_m": _finite_or_none(pose_m) if np.isfinite(pose_m).all() else None,
        "hand_joints": (_finite_or_none(arrays["hand_joints"][frame])
                        if np.isfinite(arrays["hand_joints"][frame]).all() else None),
        "objects": [{"index": o, "name": str(name),
                     "pose": _finite_or_none(arrays["object_poses"][o, frame]),
                     "confidence": round(float(confidence[o, frame]), 3),
                     "flag": str(flags[o, frame]) or None}
                    for o, name in enumerate(arrays["object_names"])],
        "kpt_error_px": {serial: _finite_or_none(errors[v]) for v, serial in enumerate(serials)},
        "depth_rms_mm": _finite_or_none(arrays["depth_rms_mm"][frame]),
    }
