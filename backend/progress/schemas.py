from __future__ import annotations

from datetime import datetime
from typing import Literal

from pydantic import BaseModel

from backend.annotation.schemas import TaskState

SequenceState = Literal["no tasks", "open", "in progress", "accepted", "solved"]


class AssignmentCounts(BaseModel):
    working: int = 0
    submitted: int = 0
    approved: int = 0
    rejected: int = 0


class TaskProgress(BaseModel):
    """One cell of the view x target grid."""

    task_id: int
    serial: str
    target_key: str
    kind: str
    state: TaskState
    # HITs published for the task (every round) and those still open for work.
    hits: int
    hits_live: int
    assignments: AssignmentCounts


class SolveProgress(BaseModel):
    run_id: int
    status: str
    # "current": made from the accepted labels as they are now; "outdated": the accepted
    # labels changed since; "by hand": asked for by an admin, not by the pipeline.
    labels: Literal["current", "outdated", "by hand"]
    finished_at: datetime | None
    error: str | None


class SequenceProgress(BaseModel):
    sequence_id: int
    subject: str
    name: str
    state: SequenceState
    views: list[str]
    targets: list[str]
    # Tasks per state (every state present, zero included).
    counts: dict[str, int]
    hits: int
    hits_live: int
    assignments: AssignmentCounts
    tasks: list[TaskProgress]
    # The sequence's latest solve run, if any.
    solve: SolveProgress | None
