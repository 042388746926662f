"""What each worker has done for the project: quality over time, approval rate, median error,
working time, earnings and whether we block them; read-only, from our own records.

A worker is listed once they have a final QC report (as the QC scores count them), a
submission confirmed by the marketplace, a payment or a block. Approval counts admin and QC
decisions alike (an assignment's status); earnings are rewards of approved work and bonuses
paid, fees apart (the worker does not receive those). Working time is what the annotation page
measured on each submitted assignment.
"""

from __future__ import annotations

import statistics
from collections import defaultdict
from typing import Any

from sqlalchemy import ColumnElement, Select, func, select, union
from sqlalchemy.orm import InstrumentedAttribute, Session

from backend.annotation.models import Assignment, Task
from backend.captures.models import Sequence, Subject
from backend.crowd import pricing
from backend.crowd.models import CrowdHit, CrowdPayment, CrowdSubmission, CrowdWorkerAction
from backend.crowd.schemas import (
    WorkerAssignmentRead,
    WorkerDetailRead,
    WorkerReportPoint,
    WorkerStatsRead,
)
from backend.errors import NotFound
from backend.labels import ACCEPTED
from backend.quality.models import QCReport
from backend.quality.service import qc_score

# Reports a listing row carries for its sparkline (the newest ones); a worker's own page
# carries up to HISTORY_DETAIL, and their newest ASSIGNMENTS_DETAIL assignments.
HISTORY_ROW = 30
_Column = ColumnElement[Any] | InstrumentedAttribute[Any]
HISTORY_DETAIL = 500
ASSIGNMENTS_DETAIL = 200


def _known_workers() -> Select[Any]:
    """Every worker id the crowd pages list (see the module's docstring), once each."""
    # Each part is made distinct on its own (by its index where there is one), so the union
    # sorts a few hundred ids, not every report, submission and payment of the project.
    return union(
        select(QCReport.worker_id.label("worker_id")).where(QCReport.provisional.is_(False))
        .distinct(),
        select(CrowdSubmission.worker_id).distinct(),
        select(CrowdPayment.worker_id).distinct(),
        select(CrowdWorkerAction.worker_id).where(CrowdWorkerAction.kind == "block").distinct(),
    ).subquery().select()


def _medians(session: Session, value: _Column, worker: _Column,
             *where: ColumnElement[bool]) -> dict[str, float]:
    """The median of ``value`` per worker (rounded to 0.001) over the rows ``where`` selects.
    PostgreSQL takes it (a big project's workers have thousands of rows each); SQLite, which
    has no percentile, hands the values over."""
    where = (*where, value.is_not(None))
    if session.get_bind().dialect.name == "postgresql":
        rows = session.execute(select(worker, func.percentile_cont(0.5).within_group(value))
                               .where(*where).group_by(worker))
        return {wid: round(float(m), 3) for wid, m in rows}
    values: dict[str, list[float]] = defaultdict(list)
    for wid, v in session.execute(select(worker, value).where(*where)):
        values[wid].append(float(v))
    return {wid: round(statistics.median(vs), 3) for wid, vs in values.items()}


def _history(session: Session, worker_ids: list[str], limit: int
             ) -> dict[str, list[WorkerReportPoint]]:
    """Each worker's QC reports by date, the newest ``limit`` of them, oldest first."""
    error = QCReport.metrics["median_error_px"].as_float()
    rank = func.row_number().over(partition_by=QCReport.worker_id,
                                  order_by=(QCReport.created_at.desc(), QCReport.id.desc()))
    newest = (select(QCReport.worker_id, QCReport.assignment_id, QCReport.created_at,
                     QCReport.outcome, QCReport.provisional, error.label("error"),
                     rank.label("rank"))
              .where(QCReport.worker_id.in_(worker_ids)).subquery())
    rows = session.execute(select(newest).where(newest.c.rank <= limit)
                           .order_by(newest.c.worker_id, newest.c.created_at,
                                     newest.c.assignment_id))
    out: dict[str, list[WorkerReportPoint]] = defaultdict(list)
    for wid, aid, at, outcome, provisional, err, _ in rows:
        out[wid].append(WorkerReportPoint(assignment_id=aid, at=at, outcome=outcome,
                                          provisional=provisional, median_error_px=err))
    return out


def _errors(session: Session, worker_ids: list[str]) -> dict[str, float]:
    """The median of the measured median errors (px) of each worker's reports."""
    return _medians(session, QCReport.metrics["median_error_px"].as_float(), QCReport.worker_id,
                    QCReport.worker_id.in_(worker_ids))


def _scores(session: Session, worker_ids: list[str]) -> dict[str, tuple[int, float | None]]:
    """Final reports and the running QC score of each worker, counted as /api/qc/workers
    does: approvals and half the reviews over every final report."""
    tally: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for wid, outcome, n in session.execute(
            select(QCReport.worker_id, QCReport.outcome, func.count())
            .where(QCReport.worker_id.in_(worker_ids), QCReport.provisional.is_(False))
            .group_by(QCReport.worker_id, QCReport.outcome)):
        tally[wid][outcome] = int(n)
    return {wid: (sum(tally.get(wid, {}).values()), qc_score(tally.get(wid, {})))
            for wid in worker_ids}


def _work(session: Session, worker_ids: list[str]
          ) -> tuple[dict[str, dict[str, int]], dict[str, float]]:
    """Per worker: assignments per status, and the median working time of submitted ones."""
    counts: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for wid, status, n in session.execute(
            select(Assignment.worker_id, Assignment.status, func.count())
            .where(Assignment.worker_id.in_(worker_ids))
            .group_by(Assignment.worker_id, Assignment.status)):
        counts[wid][status] = int(n)
    times = _medians(session, Assignment.working_time_s, Assignment.worker_id,
                     Assignment.worker_id.in_(worker_ids), Assignment.submitted_at.is_not(None))
    return counts, times


def _earnings(session: Session, worker_ids: list[str]) -> dict[str, tuple[int, int]]:
    """(reward cents of approved work, bonus cents paid) per worker."""
    out: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    for wid, kind, cents in session.execute(
            select(CrowdPayment.worker_id, CrowdPayment.kind, func.sum(CrowdPayment.amount_cents))
            .where(CrowdPayment.worker_id.in_(worker_ids), CrowdPayment.state == "done",
                   CrowdPayment.kind.in_(("approval", "bonus")))
            .group_by(CrowdPayment.worker_id, CrowdPayment.kind)):
        out[wid][0 if kind == "approval" else 1] += int(cents or 0)
    return {wid: (v[0], v[1]) for wid, v in out.items()}


def _blocks(session: Session, worker_ids: list[str]) -> dict[str, str | None]:
    rows = session.execute(
        select(CrowdWorkerAction.worker_id, CrowdWorkerAction.reason)
        .where(CrowdWorkerAction.worker_id.in_(worker_ids), CrowdWorkerAction.kind == "block"))
    return dict(rows.all())


def worker_stats(session: Session, worker_ids: list[str], history: int = HISTORY_ROW
                 ) -> list[WorkerStatsRead]:
    """The stats of each of ``worker_ids``, in that order, in a few grouped queries."""
    if not worker_ids:
        return []
    scores = _scores(session, worker_ids)
    counts, times = _work(session, worker_ids)
    errors = _errors(session, worker_ids)
    earned = _earnings(session, worker_ids)
    blocks = _blocks(session, worker_ids)
    reports = _history(session, worker_ids, history)
    out = []
    for wid in worker_ids:
        c = counts.get(wid, {})
        decided = c.get(ACCEPTED, 0) + c.get("rejected", 0)
        rewards, bonuses = earned.get(wid, (0, 0))
        scored, score = scores[wid]
        out.append(WorkerStatsRead(
            worker_id=wid, submitted=sum(c.get(s, 0) for s in ("submitted", ACCEPTED,
                                                                "rejected")),
            approved=c.get(ACCEPTED, 0), rejected=c.get("rejected", 0),
            approval_rate=round(c.get(ACCEPTED, 0) / decided, 4) if decided else None,
            scored=scored, score=score, median_error_px=errors.get(wid),
            median_working_time_s=times.get(wid),
            earned_rewards=pricing.cents_to_dollars(rewards),
            earned_bonuses=pricing.cents_to_dollars(bonuses),
            earned=pricing.cents_to_dollars(rewards + bonuses),
            blocked=wid in blocks, block_reason=blocks.get(wid),
            history=reports.get(wid, [])))
    return out


def list_workers(session: Session, limit: int, offset: int) -> list[WorkerStatsRead]:
    """``limit`` workers by id from ``offset`` on, each with their stats."""
    known = _known_workers().subquery()
    ids = list(session.scalars(select(known.c.worker_id).order_by(known.c.worker_id)
                               .offset(offset).limit(limit)))
    return worker_stats(session, ids)


def _assignments(session: Session, worker_id: str) -> list[WorkerAssignmentRead]:
    """The worker's newest assignments with what they were paid and how QC judged them."""
    bonus = (select(func.sum(CrowdPayment.amount_cents))
             .where(CrowdPayment.assignment_id == Assignment.id, CrowdPayment.kind == "bonus",
                    CrowdPayment.state == "done").scalar_subquery())
    confirmed = (select(CrowdSubmission.id)
                 .where(CrowdSubmission.assignment_id == Assignment.id).exists())
    rows = session.execute(
        select(Assignment.id, Assignment.status, Assignment.submitted_at,
               Assignment.working_time_s, Task.id, Task.target_key, Sequence.id, Sequence.name,
               Subject.name, CrowdHit.reward_cents, bonus, confirmed, QCReport.outcome,
               QCReport.metrics["median_error_px"].as_float())
        .join(Task, Task.id == Assignment.task_id)
        .join(Sequence, Sequence.id == Task.sequence_id)
        .join(Subject, Subject.id == Sequence.subject_id)
        .outerjoin(CrowdHit, CrowdHit.hit_id == Assignment.hit_id)
        .outerjoin(QCReport, QCReport.assignment_id == Assignment.id)
        .where(Assignment.worker_id == worker_id)
        .order_by(Assignment.id.desc()).limit(ASSIGNMENTS_DETAIL))
    out = []
    for (aid, status, submitted_at, seconds, task_id, target, seq_id, seq_name, subject,
         reward, bonus_cents, is_confirmed, outcome, err) in rows:
        hit_reward: int | None = reward  # no HIT (a direct link): the outer join's null
        out.append(WorkerAssignmentRead(
            assignment_id=aid, task_id=task_id, sequence_id=seq_id,
            sequence=f"{subject}/{seq_name}", target_key=target, status=status,
            submitted_at=submitted_at, working_time_s=seconds,
            reward=None if hit_reward is None else pricing.cents_to_dollars(hit_reward),
            bonuses=pricing.cents_to_dollars(int(bonus_cents or 0)),
            confirmed=bool(is_confirmed), qc_outcome=outcome, median_error_px=err))
    return out


def get_worker_or_raise(session: Session, worker_id: str) -> WorkerDetailRead:
    """One worker's stats, their whole report history and their newest assignments.

    Raises:
        NotFound: the worker has no assignment and no block here.
    """
    assignments = _assignments(session, worker_id)
    [stats] = worker_stats(session, [worker_id], HISTORY_DETAIL)
    if not assignments and not stats.blocked:
        raise NotFound(f"worker {worker_id} has no work and no block in this project")
    return WorkerDetailRead(**stats.model_dump(), assignments=assignments)
