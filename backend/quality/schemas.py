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
