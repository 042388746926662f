"""Inspecting a finished run: its frames that need a look, and how two runs differ.

World frame, metres in storage; the answers are in millimetres and degrees. A frame needs a
look where an object pose is flagged as not trusted (the reason is the solver's), an object
pose's confidence is below LOW_CONFIDENCE, or the hand could not be solved there (the reason
says why). Two runs of one sequence differ per frame by the hand joints' distance (mean and
largest over the 21 joints) and, per object, by the mean distance of its mesh vertices under
the two poses (ADD), the distance between the two origins and the angle of the relative
rotation; a frame where either run has no value has None.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.captures.assets import load_mesh
from backend.captures.models import SceneObject
from backend.errors import DexlabelError
from backend.solve.models import SolveRun
from backend.solve.pictures import run_arrays
from backend.solve.results import object_trust
from backend.solve.service import finished_run_or_raise
from backend.storage import get_storage

# Below this confidence (0..1, see worker.solver.confidence) an unflagged pose still asks for
# a look: its evidence is at most half what makes it fully supported.
LOW_CONFIDENCE = 0.5
# Rows in a comparison's table of largest differences.
LARGEST_ROWS = 10


class RunsNotComparable(DexlabelError, status_code=422, code="not_comparable"):
    pass


def _rounded(values: np.ndarray, digits: int = 3) -> list[float | None]:
    return [round(float(v), digits) if np.isfinite(v) else None for v in values]


def _frame_mean_px(errors: np.ndarray) -> np.ndarray:
    """(F,) mean reprojection error over views and joints, NaN where none is observed."""
    finite = np.isfinite(errors)
    count = finite.sum(axis=(1, 2))
    total = np.where(finite, errors, 0.0).sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def run_timeline(run: SolveRun) -> dict[str, Any]:
    """Per frame of a finished run: labelled, why not, mean reprojection error (px), the lowest
    object confidence; and the frames that need a look with their reasons."""
    arrays = run_arrays(run)
    confidence, flags = object_trust(arrays)
    names = [str(n) for n in arrays["object_names"]]
    labelled = np.asarray(arrays["labelled"], dtype=bool)
    hand = bool(str(arrays["hand_side"]))
    lowest = confidence.min(axis=0) if confidence.size else np.ones(len(labelled))
    frames, flagged = [], []
    for f in range(len(labelled)):
        reasons = [f"{names[o]}: {flags[o, f]}" for o in range(flags.shape[0]) if flags[o, f]]
        reasons += [f"{names[o]}: low confidence {confidence[o, f]:.2f}"
                    for o in range(flags.shape[0])
                    if not flags[o, f] and confidence[o, f] < LOW_CONFIDENCE]
        reason = str(arrays["reasons"][f])
        if hand and not labelled[f] and reason:
            reasons.insert(0, f"hand: {reason}")
        frames.append({"frame": f, "labelled": bool(labelled[f]), "reason": reason or None,
                       "min_confidence": round(float(lowest[f]), 3)})
        if reasons:
            flagged.append({"frame": f, "min_confidence": round(float(lowest[f]), 3),
                            "reasons": reasons})
    for row, px in zip(frames, _rounded(_frame_mean_px(arrays["kpt_error_px"])), strict=True):
        row["kpt_px_mean"] = px
    return {"run_id": run.id, "num_frames": len(labelled), "frames": frames,
            "flagged": flagged}


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...) angle (degrees) of the rotation taking a's rotation block to b's; (..., 3, >=3)."""
    relative = np.swapaxes(a[..., :3, :3], -1, -2) @ b[..., :3, :3]
    cosine = (np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def pose_differences(vertices: np.ndarray, a: np.ndarray, b: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ADD (mm), origin distance (mm), rotation angle (deg), each (F,), between poses a and b
    (F, 3, 4) of a mesh with vertices (N, 3) in its own frame; NaN where either is missing."""
    pa = np.einsum("fij,nj->fni", a[..., :3], vertices) + a[:, None, :, 3]
    pb = np.einsum("fij,nj->fni", b[..., :3], vertices) + b[:, None, :, 3]
    add = np.linalg.norm(pa - pb, axis=-1).mean(axis=1) * 1000.0
    moved = np.linalg.norm(a[..., 3] - b[..., 3], axis=-1) * 1000.0
    return add, moved, rotation_angle_deg(a, b)


def _comparable(session: Session, run_a: int, run_b: int) -> tuple[SolveRun, SolveRun]:
    a = finished_run_or_raise(session, run_a)
    b = finished_run_or_raise(session, run_b)
    if a.sequence_id != b.sequence_id:
        raise RunsNotComparable(
            f"runs {a.id} and {b.id} solve different sequences ({a.sequence_id} and "
            f"{b.sequence_id}); compare two runs of one sequence", sequences=[
                a.sequence_id, b.sequence_id])
    if a.num_frames != b.num_frames:
        raise RunsNotComparable(f"runs {a.id} and {b.id} have {a.num_frames} and "
                                f"{b.num_frames} frames; compare runs of the same frames")
    return a, b


def _largest(hand_mm: np.ndarray, objects: list[dict[str, Any]],
             add: list[np.ndarray]) -> list[dict[str, Any]]:
    """The LARGEST_ROWS largest differences (mm) over frames, hand and objects."""
    rows: list[dict[str, Any]] = [
        {"frame": f, "target": "hand", "object_index": None, "mm": float(v), "deg": None}
        for f, v in enumerate(hand_mm) if np.isfinite(v)]
    for obj, values in zip(objects, add, strict=True):
        rows += [{"frame": f, "target": obj["name"], "object_index": obj["index"],
                  "mm": float(v), "deg": obj["rotation_deg"][f]}
                 for f, v in enumerate(values) if np.isfinite(v)]
    rows.sort(key=lambda r: (-r["mm"], r["frame"]))
    for row in rows[:LARGEST_ROWS]:
        row["mm"] = round(row["mm"], 3)
    return rows[:LARGEST_ROWS]


def compare_runs(session: Session, run_a: int, run_b: int) -> dict[str, Any]:
    """How two finished runs of one sequence differ, frame by frame (see the module)."""
    a, b = _comparable(session, run_a, run_b)
    arrays_a, arrays_b = run_arrays(a), run_arrays(b)
    joints = np.linalg.norm(arrays_a["hand_joints"] - arrays_b["hand_joints"], axis=-1) * 1000.0
    hand_mm, hand_max = joints.mean(axis=1), joints.max(axis=1)
    count = min(arrays_a["object_poses"].shape[0], arrays_b["object_poses"].shape[0])
    scene = {o.index: o for o in session.scalars(
        select(SceneObject).where(SceneObject.sequence_id == a.sequence_id))}
    objects, add_values = [], []
    for o in range(count):
        mesh = load_mesh(get_storage(), scene[o].mesh_key)
        add, moved, angle = pose_differences(
            np.asarray(mesh.vertices, dtype=np.float64), arrays_a["object_poses"][o],
            arrays_b["object_poses"][o])
        add_values.append(add)
        objects.append({"index": o, "name": str(arrays_a["object_names"][o]),
                        "add_mm": _rounded(add), "translation_mm": _rounded(moved),
                        "rotation_deg": _rounded(angle)})
    finite_hand = hand_mm[np.isfinite(hand_mm)]
    return {
        "run_a": a.id, "run_b": b.id, "sequence_id": a.sequence_id, "num_frames": a.num_frames,
        "hand_mm": _rounded(hand_mm), "hand_max_mm": _rounded(hand_max),
        "hand_mean_mm": round(float(finite_hand.mean()), 3) if finite_hand.size else None,
        "objects": objects, "largest": _largest(hand_mm, objects, add_values),
    }
