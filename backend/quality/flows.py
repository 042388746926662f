"""The QC job's own work: score a target, then act on each new decision in its own unit of
work (backend.pipeline runs it and moves on to the solve).

Marketplace calls happen with no write transaction open (the embedded SQLite database is
shared with the built-in marketplace); each action's ledger row, the report's ``action`` and the
job's count of it are committed together, so a job killed at any point and run again repeats no
action, and its result counts the actions of every attempt.
"""

from __future__ import annotations

import contextlib
import logging
import time
from typing import Any

from sqlalchemy import func, select

from backend.annotation.models import Assignment
from backend.config import get_settings
from backend.crowd import actions, decisions
from backend.crowd.models import CrowdWorkerAction
from backend.crowd.provider import CrowdProvider, ProviderError
from backend.crowd.providers import get_provider
from backend.db import session_scope
from backend.errors import Conflict, DexlabelError
from backend.jobs.attempts import record_actions, run_actions
from backend.jobs.runner import RetryLater, check_lease, checkpoint
from backend.quality.models import ADMIN_DECIDED, QCReport
from backend.quality.service import hit_of, score_target

log = logging.getLogger(__name__)

REOPEN_PENDING = "rejected; re-opening the task"
REOPENED = "rejected; the task was re-opened with one more assignment"
GRANT_PENDING = "passed training; granting the qualification"
GRANTED = "passed training; the training qualification was granted"

# The reason code of a rejection by QC where the provider wants one (Prolific's
# rejection_category): the work is far from what the other views agree on.
QC_REJECTION_CATEGORY = "LOW_EFFORT"


def run_qc(sequence_id: int, target_key: str) -> dict[str, Any]:
    """The whole QC job of one target; returns counts for the job table."""
    timings: dict[str, float] = {}
    started = time.perf_counter()
    with session_scope() as session:
        counts = score_target(session, sequence_id, target_key, timings)
    timings["score_and_store_s"] = round(time.perf_counter() - started, 3)
    settings = get_settings()
    acted: dict[str, int] = {}
    started = time.perf_counter()
    if settings.qc_auto_actions:
        # Each action goes to the provider of the work it acts on.
        acted = act_on_reports(None, sequence_id, target_key)
        block_repeat_failures(None, sequence_id, target_key)
    timings["act_s"] = round(time.perf_counter() - started, 3)
    # Inside a job: the actions of every attempt of this run (a worker killed after some).
    return {"scored": counts, "actions": run_actions() or acted, "timings": timings}


def _pending(sequence_id: int, target_key: str) -> list[tuple[int, int]]:
    with session_scope() as session:
        rows = session.execute(select(QCReport.id, QCReport.assignment_id).where(
            QCReport.sequence_id == sequence_id, QCReport.target_key == target_key,
            (QCReport.action.is_(None))
            | QCReport.action_detail.startswith(REOPEN_PENDING, autoescape=True)
            | (QCReport.action_detail == GRANT_PENDING))
            .order_by(QCReport.id))
        return [(int(r), int(a)) for r, a in rows]


def act_on_reports(crowd: CrowdProvider | None, sequence_id: int,
                   target_key: str) -> dict[str, int]:
    done: dict[str, int] = {}
    for report_id, assignment_id in _pending(sequence_id, target_key):
        check_lease()  # an attempt that lost its job to a newer one stops before acting
        outcome = _act(crowd, report_id, assignment_id)
        if outcome:
            done[outcome] = done.get(outcome, 0) + 1
            checkpoint()
    return done


def _act(crowd: CrowdProvider | None, report_id: int, assignment_id: int) -> str | None:
    """One report's action (at most one marketplace decision, then the re-open)."""
    with session_scope() as session, session.no_autoflush:
        report = session.get_one(QCReport, report_id)
        assignment = session.get_one(Assignment, assignment_id)
        if report.action_detail == GRANT_PENDING:
            follow_up = _grant
        elif (report.action_detail or "").startswith(REOPEN_PENDING):
            follow_up = _reopen
        elif assignment.status in ("approved", "rejected"):
            report.action, report.action_detail = assignment.status, ADMIN_DECIDED
            return None
        elif report.provisional:
            report.action_detail = "waiting for more views before acting"
            return None
        elif report.outcome == "review":
            report.action_detail = "left for an admin's review"
            return None
        elif hit_of(session, assignment) is None:
            # Not from a marketplace (a direct link): the decision is recorded, nobody is paid.
            assignment.status = "approved" if report.outcome == "approve" else "rejected"
            report.action, report.action_detail = "recorded", "no marketplace submission"
            record_actions(session, {"recorded": 1})
            return "recorded"
        elif report.outcome == "approve":
            decisions.approve(session, crowd, assignment_id, None)
            report.action, report.action_detail = "approved", "approved automatically"
            record_actions(session, {"approved": 1})
            if report.method != "gold":
                return "approved"
            report.action_detail, follow_up = GRANT_PENDING, _grant
        else:
            decisions.reject(session, crowd, assignment_id,
                             decisions.fit_feedback(report.feedback), QC_REJECTION_CATEGORY)
            report.action, report.action_detail = "rejected", REOPEN_PENDING
            record_actions(session, {"rejected": 1})
            follow_up = _reopen
    follow_up(crowd, report_id, assignment_id)
    return report.action


def _grant(crowd: CrowdProvider | None, report_id: int, assignment_id: int) -> None:
    """The worker passed a training clip: grant our "passed training" qualification."""
    with session_scope() as session, session.no_autoflush:
        assignment = session.get_one(Assignment, assignment_id)
        provider = crowd if crowd is not None else get_provider(assignment.provider)
        # Conflict: granted by an earlier run whose commit was lost, or by an admin.
        with contextlib.suppress(Conflict):
            actions.grant_qualification(session, provider, assignment.worker_id, None,
                                        notify=True)
        session.get_one(QCReport, report_id).action_detail = GRANTED


class ReopenNotDone(RetryLater):
    """The marketplace did not answer a re-open; the job is retried and tries again."""


def _reopen(crowd: CrowdProvider | None, report_id: int, assignment_id: int) -> None:
    """One more assignment on the rejected work's HIT (its token makes a repeat add nothing).

    The report says what happened: re-opened; not re-opened because the HIT has expired or the
    marketplace refused (its reason, for an admin to act on); or, when the marketplace did not
    answer, still pending: the job fails this attempt and its retry (or the target's next QC
    run) tries the re-open again.
    """
    retry: ProviderError | None = None
    with session_scope() as session, session.no_autoflush:
        hit = hit_of(session, session.get_one(Assignment, assignment_id))
        report = session.get_one(QCReport, report_id)
        # (A HIT found for a submission has its marketplace id.)
        if hit is None or hit.hit_id is None:
            report.action_detail = "rejected; not re-opened: the work has no marketplace HIT"
            return
        if hit.expired_at is not None:
            report.action_detail = (f"rejected; not re-opened: HIT {hit.hit_id} has expired; "
                                    "publish the task again for more work")
            return
        try:
            actions.add_assignments(session, crowd, hit.hit_id, 1, allow_large_hits=True)
            report.action_detail = REOPENED
            return
        except ProviderError as exc:
            if exc.retryable:
                retry = exc
                report.action_detail = (f"{REOPEN_PENDING}: the marketplace could not take it now "
                                        f"({exc.detail}); trying again")
            else:
                report.action_detail = _refused(hit.hit_id, exc.detail)
        except DexlabelError as exc:
            report.action_detail = _refused(hit.hit_id, exc.detail)
        log.warning("could not re-open HIT %s: %s", hit.hit_id, report.action_detail)
    if retry is not None:  # raised after the report's detail is committed
        raise ReopenNotDone(f"re-opening HIT {hit.hit_id}: {retry.detail}") from retry


def _refused(hit_id: str, reason: object) -> str:
    return (f"rejected; NOT re-opened: the marketplace refused one more assignment on HIT "
            f"{hit_id} ({reason}); add one by hand or publish the task again")


def block_repeat_failures(crowd: CrowdProvider | None, sequence_id: int,
                          target_key: str) -> list[str]:
    """Block the target's workers whose final rejected reports reached the limit."""
    limit = get_settings().qc_block_after_failures
    if limit <= 0:
        return []
    with session_scope() as session:
        workers = set(session.scalars(select(QCReport.worker_id).where(
            QCReport.sequence_id == sequence_id, QCReport.target_key == target_key)))
        stmt = (select(QCReport.worker_id, func.count()).where(
            QCReport.worker_id.in_(workers), QCReport.outcome == "reject",
            QCReport.provisional.is_(False)).group_by(QCReport.worker_id))
        due = [wid for wid, count in session.execute(stmt) if count >= limit]
        blocked = set(session.scalars(select(CrowdWorkerAction.worker_id).where(
            CrowdWorkerAction.kind == "block")))
    done = []
    for worker_id in due:
        if worker_id in blocked:
            continue
        check_lease()
        with session_scope() as session, session.no_autoflush:
            try:
                actions.block_worker(session, crowd, worker_id,
                                     f"{limit} or more assignments failed the quality check")
                done.append(worker_id)
            except Conflict:
                pass
    return done
