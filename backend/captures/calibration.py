"""Calibration versions: refined calibrations of a sequence's rig, kept beside the imported one.

The imported calibration stays in the ``cameras`` rows and is never changed by a refinement.
A refinement (from the rig-health estimate, backend.rig) is a new numbered version holding, per
camera serial, its camera-to-world extrinsics (3x4, metres), time offset (whole frames: the
camera's frame ``f`` shows world time ``f - k``), depth scale and depth shift (px: the depth
map's pixel ``q + shift`` holds the depth of colour pixel ``q``), with the report it came from.
A version may also hold a hand's shape (MANO betas) fitted to the labels where the imported one
was named off. At most one version per sequence is in use; none in use means the imported
calibration. Every reader of camera models (solve, QC, export) takes them through
:func:`calibrated_models`, and the solve takes a hand's shape through :func:`hand_betas`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sqlalchemy import (
    JSON,
    Boolean,
    Index,
    Integer,
    String,
    UniqueConstraint,
    select,
    text,
)
from sqlalchemy.orm import Mapped, Session, mapped_column

from backend.captures.models import Camera
from backend.db import Base, TimestampMixin, parent_key
from worker.geometry.cameras import CameraModel


class CalibrationVersion(TimestampMixin, Base):
    """One refined calibration of a sequence's cameras (version 0 is the imported one and has
    no row)."""

    __tablename__ = "calibration_versions"
    __table_args__ = (
        UniqueConstraint("sequence_id", "number"),
        # One version in use per sequence, the database's last guard.
        Index("ux_calibration_versions_in_use", "sequence_id", unique=True,
              postgresql_where=text("in_use"), sqlite_where=text("in_use")),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    sequence_id: Mapped[int] = parent_key("sequences.id", index=True)
    number: Mapped[int] = mapped_column(Integer)
    source: Mapped[str] = mapped_column(String(32), default="rig-health")
    in_use: Mapped[bool] = mapped_column(Boolean, default=False)
    # {serial: {"extrinsics": 3x4, "time_offset_frames": int, "depth_scale": float,
    #  "depth_shift_px": [dx, dy]}}
    cameras: Mapped[dict[str, Any]] = mapped_column(JSON)
    # The rig-health report the version came from (backend.rig.schemas.RigHealthRead).
    report: Mapped[dict[str, Any]] = mapped_column(JSON)
    # {str(hand index): {"betas": [10 floats]}} for hands whose shape the version refines.
    hands: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True, default=None)


def version_in_use(session: Session, sequence_id: int) -> CalibrationVersion | None:
    """The sequence's calibration version in use, or None for the imported calibration."""
    return session.scalar(select(CalibrationVersion).where(
        CalibrationVersion.sequence_id == sequence_id, CalibrationVersion.in_use.is_(True)))


def imported_model(camera: Camera) -> CameraModel:
    """A camera row's imported calibration (pixels, camera-to-world metres)."""
    K = np.array([[camera.fx, 0.0, camera.ppx], [0.0, camera.fy, camera.ppy], [0.0, 0.0, 1.0]])
    dist = np.zeros(5)
    coeffs = np.asarray(camera.distortion or [], dtype=np.float64)[:5]
    dist[: len(coeffs)] = coeffs
    return CameraModel(K=K, dist=dist, T_cam_to_world=np.asarray(camera.extrinsics, float),
                       width=camera.width, height=camera.height)


def camera_entry(version: CalibrationVersion | None, camera: Camera) -> dict[str, Any]:
    """One camera's entry of a version (the imported values where there is none)."""
    entry = {} if version is None else dict(version.cameras.get(camera.serial, {}))
    entry.setdefault("extrinsics", camera.extrinsics)
    entry.setdefault("time_offset_frames", 0)
    entry.setdefault("depth_scale", 1.0)
    entry.setdefault("depth_shift_px", [0, 0])
    return entry


def calibrated_models(session: Session, cameras: list[Camera]) -> list[CameraModel]:
    """Camera models of ``cameras`` (one sequence) under the calibration version in use."""
    if not cameras:
        return []
    version = version_in_use(session, cameras[0].sequence_id)
    models = []
    for camera in cameras:
        model = imported_model(camera)
        entry = camera_entry(version, camera)
        models.append(CameraModel(K=model.K, dist=model.dist,
                                  T_cam_to_world=np.asarray(entry["extrinsics"], float),
                                  width=model.width, height=model.height))
    return models


def hand_betas(version: CalibrationVersion | None, hand_index: int,
               imported: list[float] | None) -> list[float] | None:
    """A hand's betas under ``version``: its refined shape where the version has one, else the
    imported betas (mano.yml or calibrate-hand)."""
    refined = None if version is None or not version.hands else version.hands.get(str(hand_index))
    return imported if refined is None else [float(b) for b in refined["betas"]]


def time_offsets(session: Session, cameras: list[Camera]) -> list[int]:
    """Each camera's time offset (whole frames) under the version in use (0 when imported)."""
    version = None if not cameras else version_in_use(session, cameras[0].sequence_id)
    return [int(camera_entry(version, c)["time_offset_frames"]) for c in cameras]
