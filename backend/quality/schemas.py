"""QC reports, worker quality and training clips as admins read and write them."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from backend.validation import BodyId, Finite, Int32


class QCReportRead(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    assignment_id: int
    task_id: int
    sequence_id: int
    target_key: str
    worker_id: str
    method: str
    outcome: str
    provisional: bool
    views: int
    reasons: list[str]
    feedback: str
    metrics: dict[str, Any]
    swaps: list[Any]
    thresholds: dict[str, Any]
    action: str | None
    action_detail: str | None
    updated_at: datetime


class QCReportDetail(QCReportRead):
    """With the per-joint and per-frame breakdowns the review page draws."""

    per_joint: list[Any]
    per_frame: list[Any]


class QCRunRequest(BaseModel):
    sequence_id: BodyId
    # Unset: every target of the sequence that has submitted work.
    target_key: str | None = Field(default=None, pattern=r"^(hand|object):\d+$")


class WorkerQualityRead(BaseModel):
    worker_id: str
    scored: int
    approved: int
    review: int
    rejected: int
    score: float
    blocked: bool


class TrainingClipCreate(BaseModel):
    """Gold labels for a task: from an accepted assignment, or given (P tracks of rows)."""

    task_id: BodyId
    from_assignment_id: BodyId | None = None
    tracks: list[list[list[Int32 | Finite | None]]] | None = None
    note: str | None = Field(default=None, max_length=1000)


class TrainingClipRead(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    task_id: int
    source: str
    note: str | None


class ReviewFrames(BaseModel):
    """The view's colour frames as an <img> loads them: one link per frame, each with a view
    token (``token``, valid ``expires_in`` seconds), and the whole view in one bundle."""

    token: str
    expires_in: int
    urls: list[str]
    bundle_url: str


class ReviewRead(BaseModel):
    """One assignment as the review page replays it. Pixels x right, y down, in the view's
    image (``width`` x ``height``); arrays by frame, then point; None where absent.

    track: {"xy" (F, P, 2), "visible" (F, P) 0/1 (0: the worker marked it occluded),
    "keyframes" per point the frames the worker set}. reference (F, P, 2): where the other
    views place each point without this label ("consensus"), or where the solved object's
    anchored landmark reprojects ("anchored"); errors (F, P) px from the track to it;
    reference_shown (F, P) 0/1 whether the solve sees an anchored landmark. Without a
    reference all three are None and reference_note says why.
    """

    assignment_id: int
    task_id: int
    sequence_id: int
    sequence: str
    serial: str
    kind: str
    target_key: str
    worker_id: str
    assignment_status: str
    num_frames: int
    width: int
    height: int
    point_names: list[str]
    point_colours: list[str]
    skeleton: list[list[int]]
    track: dict[str, Any]
    reference_source: str | None
    reference: list[Any] | None
    errors: list[Any] | None
    reference_shown: list[Any] | None
    reference_note: str | None
    swaps: list[Any]
    issues: list[Any]
    reasons: list[str]
    feedback: str
    outcome: str
    provisional: bool
    views: int
    method: str
    metrics: dict[str, Any]
    thresholds: dict[str, Any]
    per_joint: list[Any]
    per_frame: list[Any]
    action: str | None
    action_detail: str | None
    highlight: dict[str, Any] | None
    frames: ReviewFrames


class QueueItem(BaseModel):
    """One report waiting for an admin: enough to show its row in the review queue."""

    assignment_id: int
    sequence_id: int
    sequence: str
    target_key: str
    worker_id: str
    method: str
    outcome: str
    provisional: bool
    views: int
    # The report's median error, px (raw against the views, or against the solved object).
    error_px: float | None
    swaps: int
    issues: int
    reasons: list[str]
    action_detail: str | None
    updated_at: datetime


class QueueRead(BaseModel):
    total: int
    offset: int
    limit: int
    items: list[QueueItem]
