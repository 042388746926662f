"""Solve runs and their per-frame outputs as the API reads and writes them."""

from __future__ import annotations

from datetime import datetime
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from backend.validation import Finite, Scalar

Optimiser = Literal["paper", "default"]


class SolveRequest(BaseModel):
    """Body of POST /api/sequences/{id}/solve; the optimiser defaults to the setting.

    params: overrides of worker.solver.SolveSettings fields (weights, iterations, use_depth,
    ...), e.g. {"w_depth": 0.5}; unknown names are refused.
    """

    model_config = ConfigDict(extra="forbid")

    optimiser: Optimiser | None = None
    params: dict[str, Scalar] | None = None


class SolveRunRead(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    sequence_id: int
    optimiser: str
    params: dict[str, Any]
    status: str
    timings: dict[str, Any]
    summary: dict[str, Any] | None
    error: str | None
    num_frames: int
    num_views: int
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    # True for the sequence's newest finished run: the one its results come from.
    current: bool = False


class ObjectPose(BaseModel):
    """One object's solved pose (object-to-world 3x4, metres), how well its evidence supports
    it (confidence 0..1) and, for a pose that is not trusted, the reason (then it is exported
    as unlabelled)."""

    index: int
    name: str
    pose: list[list[float | None]]
    confidence: float = 1.0
    flag: str | None = None


class SolveFrameRead(BaseModel):
    """One frame's outputs: world frame, metres; errors in pixels and millimetres."""

    run_id: int
    frame: int
    labelled: bool
    reason: str | None
    # How well the evidence pins the hand down on this frame (0-1), and why it is not trusted
    # (None: trusted); a flagged frame's pose is kept beside its flag.
    hand_confidence: float = 1.0
    hand_flag: str | None = None
    hand_pose_m: list[float] | None
    hand_joints: list[list[float]] | None
    objects: list[ObjectPose]
    # serial -> 21 joint errors (px), None where the joint is not labelled in that view.
    kpt_error_px: dict[str, list[float | None]]
    depth_rms_mm: float | None
    hand_vertices: list[list[float]] | None = None
    hand_faces: list[list[int]] | None = None


class InitialPoseUpdate(BaseModel):
    """Object-to-world 3x4 pose at the first frame, metres, with a rotation block."""

    model_config = ConfigDict(extra="forbid")

    pose: list[list[Finite]] = Field(min_length=3, max_length=3)

    @field_validator("pose")
    @classmethod
    def _three_by_four(cls, pose: list[list[float]]) -> list[list[float]]:
        if any(len(row) != 4 for row in pose):
            raise ValueError("pose must be 3 rows of 4 numbers (object-to-world, metres)")
        return pose


class FrameState(BaseModel):
    """One frame of a run at a glance: labelled (hand solved), why not, mean reprojection
    error (px) over views and joints, the lowest object confidence (0..1)."""

    frame: int
    labelled: bool
    reason: str | None
    kpt_px_mean: float | None
    min_confidence: float


class FlaggedFrame(BaseModel):
    """A frame that needs a look and why (object flags, low confidence, hand not solved)."""

    frame: int
    min_confidence: float
    reasons: list[str]


class RunTimeline(BaseModel):
    run_id: int
    num_frames: int
    frames: list[FrameState]
    flagged: list[FlaggedFrame]


class ObjectDifference(BaseModel):
    """Per frame, how far one object's pose differs between two runs: mean mesh-vertex
    distance (ADD, mm), origin distance (mm), relative rotation (degrees); None where either
    run has no pose."""

    index: int
    name: str
    add_mm: list[float | None]
    translation_mm: list[float | None]
    rotation_deg: list[float | None]


class LargestDifference(BaseModel):
    """One of the largest differences: the hand's mean joint distance or an object's ADD (mm)
    at a frame; deg is the object's relative rotation (None for the hand)."""

    frame: int
    target: str
    object_index: int | None
    mm: float
    deg: float | None


class RunComparison(BaseModel):
    """How run_b differs from run_a, per frame (hand joints: mean and largest over the 21
    joints, mm; objects: see ObjectDifference); the largest differences first in ``largest``."""

    run_a: int
    run_b: int
    sequence_id: int
    num_frames: int
    hand_mm: list[float | None]
    hand_max_mm: list[float | None]
    hand_mean_mm: float | None
    objects: list[ObjectDifference]
    largest: list[LargestDifference]


class SolveSettingsRead(BaseModel):
    """The settings a run of ``optimiser`` gets when a request overrides none of them."""

    optimiser: Optimiser
    params: dict[str, Any]
    # Each setting's kind: "bool", "int" or "float" (JSON writes 1.0 as 1).
    kinds: dict[str, str]
