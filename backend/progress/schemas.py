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
    # Why the task's first unit was published under the adaptive policy (backend.crowd.
    # adaptive), e.g. "initial: widest baselines (views 0, 3, 5 of 8)"; None under every view.
    publish_reason: str | None = None
    # Held back by the adaptive policy: published only if a solve needs the view.
    held: bool = False


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
    # How its views are published: "every-view" (all at once) or "adaptive" (held tasks wait
    # for a solve that needs them; the state counts the others).
    publish_policy: str = "every-view"
    held: int = 0
    # The sequence's latest solve run, if any.
    solve: SolveProgress | None


class TargetFrameCost(BaseModel):
    """What one target (a hand or an object) of a sequence cost in human work and money, and
    that cost per labelled 3D frame (None while no frame is labelled).

    actions: edit actions (clicks, drags, keys) the annotation page counted in every assignment
    of the target's tasks; seconds: their active working time; money: the ledger's spend on
    them (approved rewards and paid bonuses, each with the provider's fee), a decimal string in
    ``currency`` ("mixed" where providers of different currencies were paid).
    frames_labelled: frames the current solve labelled for the target and did not flag.
    label: the target as people name it ("right hand", "object 1 (003_cracker_box)").
    """

    target_key: str
    label: str
    kind: str
    views: int
    assignments: int
    frames: int
    frames_labelled: int
    actions: int
    seconds: float
    money: str
    money_cents: int
    currency: str
    actions_per_frame: float | None
    seconds_per_frame: float | None
    money_per_frame: str | None


class SequenceFrameCost(BaseModel):
    """A sequence's cost per labelled 3D frame, per target and in total.

    The total's frames_labelled counts the frames labelled for every target at once (a frame
    whose hand and objects are all trusted); its actions, seconds and money add up the
    targets'. solve_run_id: the solve result the labelled frames come from (None: none yet).
    """

    sequence_id: int
    name: str
    solve_run_id: int | None
    targets: list[TargetFrameCost]
    total: TargetFrameCost
