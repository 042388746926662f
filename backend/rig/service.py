"""Rig health and calibration versions: what is read, stored and put in use.

The estimate reads the accepted hand labels through the solve's read path (backend.solve.inputs:
the approved assignments of every view, merged per view) and every view's aligned depth, and
always starts from the imported calibration, so each version is a refinement of the import.
The subject's hand shape (the imported betas) is checked against the bones of the labels
triangulated under the refined rig; where it is off, the version carries the fitted betas.
The computation itself (worker.rig) runs outside any unit of work (backend.rig.flows).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import cv2
import numpy as np
from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from backend.captures.assets import hand_model_for, load_depth
from backend.captures.calibration import CalibrationVersion, imported_model, version_in_use
from backend.captures.models import Frame
from backend.captures.service import get_sequence_or_raise, sequence_cameras
from backend.errors import Conflict, NotFound
from backend.jobs.models import Job
from backend.jobs.service import enqueue_job
from backend.labels import approved_labels, count_accepted
from backend.rig.schemas import CameraHealthRead, HandShapeRead, RigHealthRead, RigHealthStatus
from backend.solve.inputs import hand_target
from backend.storage import get_storage
from worker.geometry.cameras import CameraModel
from worker.hand.calibrate import SHAPE_BONE_MM, check_shape, triangulate_joints
from worker.rig import RigEstimate, RigThresholds, apply_time_offsets, estimate_rig

JOB_KIND = "rig_health"
# Colour frames per view the depth registration looks at (edges of a few frames suffice).
COLOR_FRAMES = 3


def job_key(sequence_id: int) -> str:
    return f"rig_health:{sequence_id}"


@dataclass
class RigInputs:
    """One sequence's rig as imported and its accepted hand labels: V serials and cameras,
    keypoints (V, F, 21, 2) px, visible (V, F, 21), depth V x (F, H, W) uint16 mm or None,
    color V x {frame: (H, W, 3) uint8} of COLOR_FRAMES frames, the master's view (the world
    frame), how many accepted assignments there were, and the hand: its side, calibration name
    and imported betas (None: no shape to check)."""

    sequence_id: int
    serials: list[str]
    cameras: list[CameraModel]
    keypoints: np.ndarray
    visible: np.ndarray
    depth: list[np.ndarray | None]
    color: list[dict[int, np.ndarray]]
    master_view: int
    assignments: int
    hand_side: str = "right"
    hand_calib: str | None = None
    betas: list[float] | None = None


def _color_frames(frames: list[Frame]) -> dict[int, np.ndarray]:
    """COLOR_FRAMES evenly spaced colour frames of one view, decoded: {index: (H, W, 3)}."""
    if not frames:
        return {}
    storage = get_storage()
    picks = sorted({round(float(x)) for x in np.linspace(0, len(frames) - 1, COLOR_FRAMES)})
    out = {}
    for i in picks:
        data = np.frombuffer(storage.get_bytes(frames[i].color_key), np.uint8)
        image = cv2.imdecode(data, cv2.IMREAD_COLOR)
        if image is not None:
            out[frames[i].index] = image
    return out


def read_inputs(session: Session, sequence_id: int) -> RigInputs:
    """The estimate's inputs; Conflict (409) when there is not enough to estimate from."""
    seq = get_sequence_or_raise(session, sequence_id)
    cameras = sequence_cameras(session, sequence_id)
    if len(cameras) < 3:
        raise Conflict(f"sequence {sequence_id} has {len(cameras)} cameras; rig health "
                       "needs at least 3")
    hand = hand_target(seq, cameras, approved_labels(session, sequence_id, seq.num_frames))
    if hand is None or hand.visible.any(axis=(1, 2)).sum() < 3:
        raise Conflict(f"sequence {sequence_id} has accepted hand labels in fewer than 3 "
                       "views; rig health compares views")
    storage = get_storage()
    frames = [list(session.scalars(select(Frame).where(Frame.camera_id == c.id)
                                   .order_by(Frame.index))) for c in cameras]
    depth = [load_depth(storage, c, f) for c, f in zip(cameras, frames, strict=True)]
    color = [_color_frames(f) for f in frames]
    serials = [c.serial for c in cameras]
    master = serials.index(seq.master_serial) if seq.master_serial in serials else 0
    plan = next(h for h in seq.hands if h.index == 0)
    return RigInputs(sequence_id, serials, [imported_model(c) for c in cameras],
                     hand.keypoints, hand.visible, depth, color, master,
                     count_accepted(session, sequence_id), plan.side, plan.calib_name,
                     list(plan.betas) if plan.betas else None)


def _num(x: float) -> float | None:
    return None if not np.isfinite(x) else round(float(x), 3)


def _hand_shape(inputs: RigInputs, est: RigEstimate) -> list[dict[str, Any]]:
    """The hand row of the report: the imported shape against the labels' bones, triangulated
    under the refined rig in world time ([] when the hand has no betas or too few frames)."""
    if not inputs.betas:
        return []
    keypoints, visible = apply_time_offsets(inputs.keypoints, inputs.visible,
                                            [h.time_offset_frames for h in est.health])
    try:
        check = check_shape(triangulate_joints(est.cameras, keypoints, visible),
                            np.asarray(inputs.betas), hand_model_for(inputs.hand_side))
    except ValueError:  # a bone seen in too few frames: nothing to judge the shape by
        return []
    fault = check.fault()
    return [HandShapeRead(
        index=0, side=inputs.hand_side, calib_name=inputs.hand_calib, frames=check.frames,
        bone_diff_median_mm=round(check.median_diff_mm, 2),
        bone_diff_max_mm=round(check.max_diff_mm, 2),
        fitted_betas=[round(float(b), 5) for b in check.fit.betas],
        faults=[] if fault is None else [fault]).model_dump()]


def estimate(inputs: RigInputs) -> tuple[dict[str, Any], dict[str, Any]]:
    """(cameras entry of a new version, its report) from the inputs; pure computation. The
    report's ``hands`` rows carry the fitted betas (store_version keeps those named off)."""
    limits = RigThresholds()
    est: RigEstimate = estimate_rig(inputs.cameras, inputs.keypoints, inputs.visible,
                                    inputs.depth, inputs.color, fixed=(inputs.master_view,),
                                    limits=limits)
    cameras, rows = {}, []
    for serial, h, cam in zip(inputs.serials, est.health, est.cameras, strict=True):
        cameras[serial] = {"extrinsics": cam.T_cam_to_world.tolist(),
                           "time_offset_frames": h.time_offset_frames,
                           "depth_scale": 1.0 if h.depth_scale is None else h.depth_scale,
                           "depth_shift_px": list(h.depth_shift_px or (0, 0))}
        rows.append(CameraHealthRead(
            serial=serial, view=h.view, time_offset_frames=h.time_offset_frames,
            rotation_deg=round(h.rotation_deg, 3), translation_mm=round(h.translation_mm, 2),
            image_shift_px=round(h.image_shift_px, 2),
            residual_px_before=_num(h.residual_px_before),
            residual_px_after=_num(h.residual_px_after),
            depth_scale_percent=None if h.depth_scale is None
            else round(100.0 * (h.depth_scale - 1.0), 2),
            depth_shift_px=None if h.depth_shift_px is None else list(h.depth_shift_px),
            faults=h.faults).model_dump())
    report = {"labels": inputs.assignments,
              "thresholds": {**asdict(limits), "hand_bone_mm": SHAPE_BONE_MM},
              "cameras": rows, "faulty": [inputs.serials[v] for v in est.faulty_views],
              "hands": _hand_shape(inputs, est)}
    return cameras, report


def store_version(session: Session, sequence_id: int, cameras: dict[str, Any],
                  report: dict[str, Any]) -> CalibrationVersion:
    """A new numbered version (not in use) of the sequence's calibration; it refines the
    shape of each hand the report names off."""
    get_sequence_or_raise(session, sequence_id)
    number = int(session.scalar(select(func.max(CalibrationVersion.number)).where(
        CalibrationVersion.sequence_id == sequence_id)) or 0) + 1
    hands = {str(h["index"]): {"betas": h["fitted_betas"]}
             for h in report.get("hands", []) if h["faults"]}
    version = CalibrationVersion(sequence_id=sequence_id, number=number, source="rig-health",
                                 in_use=False, cameras=cameras, report=report,
                                 hands=hands or None)
    session.add(version)
    session.flush()
    return version


def report_of(version: CalibrationVersion) -> RigHealthRead:
    return RigHealthRead(sequence_id=version.sequence_id, version=version.number,
                         in_use=version.in_use, created_at=version.created_at,
                         **version.report)


def latest_version(session: Session, sequence_id: int) -> CalibrationVersion | None:
    return session.scalar(select(CalibrationVersion).where(
        CalibrationVersion.sequence_id == sequence_id)
        .order_by(CalibrationVersion.number.desc()).limit(1))


def health_status(session: Session, sequence_id: int) -> RigHealthStatus:
    """The newest report, the version in use and the job's state; NotFound for no sequence."""
    get_sequence_or_raise(session, sequence_id)
    latest = latest_version(session, sequence_id)
    in_use = version_in_use(session, sequence_id)
    job = session.scalar(select(Job).where(Job.key == job_key(sequence_id)))
    return RigHealthStatus(sequence_id=sequence_id,
                           version_in_use=0 if in_use is None else in_use.number,
                           report=None if latest is None else report_of(latest),
                           job_status=None if job is None else job.status,
                           job_error=None if job is None else job.error)


def request_health(session: Session, sequence_id: int) -> Job:
    """Queue the rig-health job of a sequence (runs after commit)."""
    get_sequence_or_raise(session, sequence_id)
    return enqueue_job(session, JOB_KIND, job_key(sequence_id), {"sequence_id": sequence_id})


def adopt(session: Session, sequence_id: int, number: int) -> int:
    """Put version ``number`` in use (0: the imported calibration); NotFound for no such
    sequence or version. Returns the number in use."""
    get_sequence_or_raise(session, sequence_id)
    chosen = None
    if number != 0:
        chosen = session.scalar(select(CalibrationVersion).where(
            CalibrationVersion.sequence_id == sequence_id,
            CalibrationVersion.number == number))
        if chosen is None:
            raise NotFound(f"sequence {sequence_id} has no calibration version {number}")
    session.execute(update(CalibrationVersion).where(
        CalibrationVersion.sequence_id == sequence_id).values(in_use=False)
        .execution_options(synchronize_session=False))
    session.flush()
    if chosen is not None:
        session.refresh(chosen)
        chosen.in_use = True
        session.flush()
    session.expire_all()
    return number

