"""The one query for labelled work: which assignments' tracks count, for QC, the solve, the
export and pre-fill.

- accepted labels: assignments whose status is ACCEPTED (approved by QC or by an admin); the
  solve fits them, the export's default ``include="accepted"`` writes them;
- scored labels: submitted or accepted work the marketplace has vouched for (QC's consensus);
- submitted work: every assignment that was submitted, whatever became of it (the export's
  ``include="submitted"``, each with its QC outcome).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Literal

from sqlalchemy import ColumnElement, Select, exists, func, or_, select
from sqlalchemy.orm import Session, selectinload

from backend.annotation.models import Assignment, Task
from backend.crowd.models import CrowdSubmission

ACCEPTED = "approved"
ACCEPTED_STATUSES: tuple[str, ...] = (ACCEPTED,)
# Assignments whose labels take part in scoring; rejected work is left out of the consensus.
SCORED_STATUSES: tuple[str, ...] = ("submitted", ACCEPTED)
SUBMITTED_STATUSES: tuple[str, ...] = ("submitted", ACCEPTED, "rejected")
Include = Literal["accepted", "submitted"]
INCLUDE_STATUSES: dict[str, tuple[str, ...]] = {"accepted": ACCEPTED_STATUSES,
                                                "submitted": SUBMITTED_STATUSES}

# Marketplace work takes part once the requester API has vouched for it (its confirmation
# recorded a CrowdSubmission: the marketplace's record names its HIT and worker), so work on
# an assignment id the marketplace does not know never enters the consensus. Work from an
# admin's direct link has no HIT. (Correlated: each candidate assignment is looked up by the
# unique index on crowd_submissions.assignment_id, not the whole table read into a hash.)
VOUCHED_FOR: ColumnElement[bool] = or_(
    Assignment.hit_id.is_(None), exists().where(CrowdSubmission.assignment_id == Assignment.id))


def sequence_tasks(session: Session, sequence_id: int, target_key: str | None = None
                   ) -> list[Task]:
    """A sequence's tasks (of one target, if given) in id order."""
    stmt = select(Task).where(Task.sequence_id == sequence_id).order_by(Task.id)
    if target_key is not None:
        stmt = stmt.where(Task.target_key == target_key)
    return list(session.scalars(stmt))


def work_query(task_ids: Iterable[int], statuses: Sequence[str] = ACCEPTED_STATUSES,
               vouched: bool = False, with_tracks: bool = True) -> Select[Assignment]:
    """The assignments of ``task_ids`` in ``statuses`` (only vouched-for ones if ``vouched``),
    in id order, their tracks loaded in one more query."""
    stmt = select(Assignment).where(Assignment.task_id.in_(list(task_ids)),
                                    Assignment.status.in_(statuses))
    if vouched:
        stmt = stmt.where(VOUCHED_FOR)
    if with_tracks:
        stmt = stmt.options(selectinload(Assignment.tracks))
    return stmt.order_by(Assignment.id)


def labelled_work(session: Session, task_ids: Iterable[int],
                  statuses: Sequence[str] = ACCEPTED_STATUSES, vouched: bool = False
                  ) -> list[Assignment]:
    """The assignments of :func:`work_query`, with their tracks."""
    return list(session.scalars(work_query(task_ids, statuses, vouched)))


def count_accepted(session: Session, sequence_id: int) -> int:
    """How many accepted assignments the sequence has."""
    tasks = list(session.scalars(select(Task.id).where(Task.sequence_id == sequence_id)))
    stmt = select(func.count(Assignment.id)).where(Assignment.task_id.in_(tasks),
                                                   Assignment.status.in_(ACCEPTED_STATUSES))
    return int(session.scalar(stmt) or 0)


def accepted_ids_by_task(session: Session, task_ids: Iterable[int]) -> list[tuple[int, int]]:
    """(task id, assignment id) of every accepted assignment of ``task_ids``, by assignment."""
    rows = session.execute(
        select(Assignment.task_id, Assignment.id)
        .where(Assignment.task_id.in_(list(task_ids)), Assignment.status.in_(ACCEPTED_STATUSES))
        .order_by(Assignment.id)).all()
    return [(int(task_id), int(assignment_id)) for task_id, assignment_id in rows]
