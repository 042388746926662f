"""Rig-health report and calibration versions as the API returns them."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel


class CameraHealthRead(BaseModel):
    """One camera: its estimates against the imported calibration and the faults named.

    time_offset_frames: + late, - early. rotation_deg, translation_mm: the pose correction;
    image_shift_px: how far it moves the labelled points in this camera's image.
    residual_px_*: median error of this camera's labels against the other cameras' points,
    imported and refined. depth_scale_percent: (scale - 1) x 100; depth_shift_px: (dx, dy).
    """

    serial: str
    view: int
    time_offset_frames: int
    rotation_deg: float
    translation_mm: float
    image_shift_px: float
    residual_px_before: float | None
    residual_px_after: float | None
    depth_scale_percent: float | None
    depth_shift_px: list[int] | None
    faults: list[str]


class HandShapeRead(BaseModel):
    """One hand's imported shape (betas) against the bones of its labels, triangulated under
    the refined rig. bone_diff_*_mm: |model bone - labelled bone| over the 20 bones, median and
    largest; frames: frames with every joint triangulated; fitted_betas: the shape the labels
    call for (the version carries it when ``faults`` names the shape off)."""

    index: int
    side: str
    calib_name: str | None
    frames: int
    bone_diff_median_mm: float
    bone_diff_max_mm: float
    fitted_betas: list[float]
    faults: list[str]


class RigHealthRead(BaseModel):
    """The rig-health report of one calibration version."""

    sequence_id: int
    version: int
    in_use: bool
    created_at: datetime | None = None
    labels: int
    thresholds: dict[str, float]
    cameras: list[CameraHealthRead]
    faulty: list[str]
    hands: list[HandShapeRead] = []
    seconds: float | None = None


class RigHealthStatus(BaseModel):
    """The newest report (None until one was computed), the version in use (0: imported) and
    the rig-health job's state."""

    sequence_id: int
    version_in_use: int
    report: RigHealthRead | None
    job_status: str | None
    job_error: str | None = None


class AdoptRequest(BaseModel):
    """Put a version in use (0: back to the imported calibration) and, by default, re-solve."""

    solve: bool = True


class AdoptResult(BaseModel):
    sequence_id: int
    version_in_use: int
    solve: str
