"""Queue jobs: enqueue by key, claim with a lease, finish or retry with backoff, reap the dead.

Every state change is one short committed statement, guarded by a compare-and-set on the
status (and on the attempt number when finishing), so two consumers never run the same attempt
and a worker declared dead cannot overwrite the attempt that replaced it. The job's own work
runs in its own units of work between the claim and the finish.
"""

from __future__ import annotations

import importlib
import logging
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any, TypeVar, cast

from sqlalchemy import ColumnElement, CursorResult, Result, or_, select, update
from sqlalchemy.dialects.postgresql import insert as pg_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.orm import Session

from backend.config import get_settings
from backend.db import session_scope
from backend.errors import Conflict, NotFound
from backend.jobs.models import Job
from backend.queue import enqueue_after_commit, huey

log = logging.getLogger(__name__)

_CLAIMABLE = ("queued", "retrying")
_ACTIVE = ("queued", "running", "retrying")


@dataclass(frozen=True)
class Handler:
    run: Callable[[dict[str, Any]], dict[str, Any] | None]
    lease_s: float | None


_HANDLERS: dict[str, Handler] = {}
# The module whose import registers the product's job handlers; loaded by the first job run in
# a process that has not imported it (a CLI command running a job here, a test).
HANDLERS_MODULE = "worker.tasks"


JobFn = TypeVar("JobFn", bound=Callable[[dict[str, Any]], dict[str, Any] | None])


def job_handler(kind: str, lease_s: float | None = None) -> Callable[[JobFn], JobFn]:
    """Register ``fn(args) -> result dict`` as the work of jobs of ``kind``.

    The handler opens its own units of work and must be idempotent: a retry (after an error
    or a killed worker) runs it again from the start.
    """
    def register(fn: JobFn) -> JobFn:
        _HANDLERS[kind] = Handler(fn, lease_s)
        return fn
    return register


def handler_for(kind: str) -> Handler | None:
    if kind not in _HANDLERS:
        importlib.import_module(HANDLERS_MODULE)
    return _HANDLERS.get(kind)


def _now() -> datetime:
    return datetime.now(UTC)


def describe(job: Job) -> str:
    """The job's outcome in one line for people: its error while it is failing or waiting,
    else the ``message`` its handler put in the result ("qc: scored 6: 4 approve, ...")."""
    if job.status in ("failed", "retrying", "waiting") and job.error:
        return f"{job.kind}: {job.status}: {job.error.strip().splitlines()[-1]}"
    message = (job.result or {}).get("message")
    if job.status == "done" and message:
        return f"{job.kind}: {message}"
    return f"{job.kind}: {job.status}"


def get_job_or_raise(session: Session, job_id: int) -> Job:
    job = session.get(Job, job_id)
    if job is None:
        raise NotFound(f"no job {job_id}")
    return job


def list_jobs(session: Session, status: str | None = None, kind: str | None = None,
              limit: int = 100) -> list[Job]:
    stmt = select(Job).order_by(Job.id.desc()).limit(limit)
    if status:
        stmt = stmt.where(Job.status == status)
    if kind:
        stmt = stmt.where(Job.kind == kind)
    return list(session.scalars(stmt))


def enqueue_job(session: Session, kind: str, key: str, args: dict[str, Any] | None = None) -> Job:
    """Queue the job named ``key`` once this unit of work commits.

    Every ask is counted on the job's row. A job already queued (or waiting to retry) will see
    the newest data when it starts; a running one started before this unit of work's data, so
    it is queued again when its attempt ends (``_finish``). A finished, failed or waiting job
    is queued again with fresh attempts.
    """
    if _insert_new(session, kind, key, args):
        enqueue_after_commit(session, run_job, key)
        return session.scalars(select(Job).where(Job.key == key)).one()
    job = session.scalars(select(Job).where(Job.key == key)).one()
    # Counting the ask takes the row's write lock, so the status read next is the one a
    # finishing attempt will see this ask against (see _finish).
    session.execute(update(Job).where(Job.key == key).values(requests=Job.requests + 1)
                    .execution_options(synchronize_session=False))
    session.refresh(job)
    if job.status in _ACTIVE:
        return job
    job.status, job.attempts, job.error, job.args = "queued", 0, None, args or job.args
    job.finished_at = None
    session.flush()
    enqueue_after_commit(session, run_job, key)
    return job


def _insert_new(session: Session, kind: str, key: str, args: dict[str, Any] | None) -> bool:
    """Insert the job's row as queued unless the key exists (also when a concurrent unit of
    work inserts it first); True when this call made it."""
    insert = pg_insert if session.get_bind().dialect.name == "postgresql" else sqlite_insert
    now = _now()
    made = session.execute(
        insert(Job).values(kind=kind, key=key, args=args or {}, status="queued", attempts=0,
                           max_attempts=get_settings().job_max_attempts, requests=1,
                           requests_claimed=0, created_at=now, updated_at=now)
        .on_conflict_do_nothing(index_elements=["key"]).returning(Job.id))
    return made.scalar_one_or_none() is not None


def mark_waiting(session: Session, kind: str, key: str, args: dict[str, Any], reason: str) -> Job:
    """Record a job that cannot run yet (e.g. no solver installed), with the reason shown."""
    job = session.scalar(select(Job).where(Job.key == key))
    if job is None:
        job = Job(kind=kind, key=key, args=args, attempts=0,
                  max_attempts=get_settings().job_max_attempts)
        session.add(job)
    job.status, job.error = "waiting", reason
    session.flush()
    return job


def retry_job(session: Session, job_id: int) -> Job:
    """An admin's re-run of a failed or waiting job."""
    job = get_job_or_raise(session, job_id)
    if job.status in _ACTIVE:
        raise Conflict(f"job {job_id} is already {job.status}", state=job.status)
    return enqueue_job(session, job.kind, job.key, job.args)


def _rowcount(result: Result[Any]) -> int:
    """The rows an UPDATE changed (its result is a cursor result, which has a rowcount)."""
    return cast(CursorResult[Any], result).rowcount


def _claim(key: str) -> tuple[str, dict[str, Any], int] | None:
    """Take the job for this worker: (kind, args, attempt), or None when not ours to run."""
    settings = get_settings()
    with session_scope() as session:
        job = session.scalar(select(Job).where(Job.key == key))
        if job is None:
            log.warning("job %s is not in the job table; dropped", key)
            return None
        handler = handler_for(job.kind)
        lease = (handler.lease_s if handler and handler.lease_s else settings.job_lease_s)
        now = _now()
        claimed = session.execute(
            update(Job).where(Job.key == key, or_(
                Job.status.in_(_CLAIMABLE),
                (Job.status == "running") & (Job.lease_until < now)))
            .values(status="running", attempts=Job.attempts + 1, started_at=now,
                    lease_until=now + timedelta(seconds=lease), error=None,
                    requests_claimed=Job.requests)
            .execution_options(synchronize_session=False))
        if _rowcount(claimed) != 1:
            return None
        session.refresh(job)
        return job.kind, dict(job.args or {}), job.attempts


def checkpoint() -> None:
    """A point inside a job where a crash drill may kill the worker (see job_pause_s)."""
    pause = get_settings().job_pause_s
    if pause:
        time.sleep(pause)


def _finish(key: str, attempt: int, **values: Any) -> bool:
    """End attempt ``attempt`` with ``values`` (compare-and-set); False when it was not ours.

    A job that ends done or failed while asks arrived after its attempt started is queued
    again at once, so work submitted during a run is never left unprocessed.
    """
    rerun = False
    with session_scope() as session:
        done = session.execute(
            update(Job).where(Job.key == key, Job.status == "running", Job.attempts == attempt)
            .values(lease_until=None, **values).execution_options(synchronize_session=False))
        if _rowcount(done) != 1:
            return False
        if values.get("status") in ("done", "failed"):
            again = session.execute(
                update(Job).where(Job.key == key, Job.status == values["status"],
                                  Job.requests > Job.requests_claimed)
                .values(status="queued", attempts=0, finished_at=None)
                .execution_options(synchronize_session=False))
            rerun = _rowcount(again) == 1
    if rerun:
        log.info("job %s was asked for while it ran: queued again", key)
        run_job(key)
    return True


def _retry_delay(attempt: int) -> float:
    base = get_settings().job_retry_base_s
    return min(base * 2 ** (attempt - 1), 3600.0)


def execute(key: str) -> None:
    """Run one attempt of the job ``key`` (the body of the queue task)."""
    claim = _claim(key)
    if claim is None:
        return
    kind, args, attempt = claim
    handler = handler_for(kind)
    try:
        if handler is None:
            raise RuntimeError(f"no handler for jobs of kind {kind!r} in this worker")
        result = handler.run(args) or {}
    except Exception as exc:  # every failure is recorded on the job, then retried or failed
        log.exception("job %s attempt %d failed", key, attempt)
        _after_failure(key, attempt, exc)
        return
    _finish(key, attempt, status="done", result=result, finished_at=_now())


def _after_failure(key: str, attempt: int, exc: Exception) -> None:
    # "ValueError: boom" (the exception's type and message, as a traceback's last line).
    error = "".join(traceback.format_exception_only(type(exc), exc)).strip()
    with session_scope() as session:
        job = session.scalar(select(Job).where(Job.key == key))
        final = job is None or attempt >= job.max_attempts
    if final:
        _finish(key, attempt, status="failed", error=error, finished_at=_now())
        return
    if _finish(key, attempt, status="retrying", error=error):
        run_job.schedule((key,), delay=_retry_delay(attempt))


def requeue_stale(now: datetime | None = None, starting: bool = False) -> list[str]:
    """Queue again the jobs whose worker died (lease ran out) or whose message was lost.

    A consumer ``starting`` also re-sends every queued job at once: its message may have gone
    to a queue no consumer reads (a command run with other queue settings) or been lost while
    none ran. A duplicate message is harmless, the claim runs a job once.
    """
    settings = get_settings()
    now = now or _now()
    lost_before = now - timedelta(seconds=settings.job_requeue_after_s)
    with session_scope() as session:
        stale: list[ColumnElement[bool]] = [
            (Job.status == "running") & (Job.lease_until < now),
            Job.status.in_(_CLAIMABLE) & (Job.updated_at < lost_before)]
        if starting:
            stale.append(Job.status == "queued")
        rows = session.execute(select(Job.key, Job.status, Job.updated_at)
                               .where(or_(*stale))).all()
        for key, _, _ in rows:
            # Touch the row so a lost message is re-sent once per interval, not every minute.
            session.execute(update(Job).where(Job.key == key, Job.status != "running")
                            .values(updated_at=now).execution_options(synchronize_session=False))
    for key, status, updated_at in rows:
        if status == "running":
            log.warning("job %s: its worker stopped before the lease ran out; queued again", key)
        elif _aware(updated_at) < lost_before:
            log.warning("job %s: queued for over %.0f s with no worker taking it; its message "
                        "is sent again", key, settings.job_requeue_after_s)
        else:  # queued recently, before this consumer started: routine, not a fault
            log.info("job %s: queued before this worker started; sent to it", key)
        run_job(key)
    return [key for key, _, _ in rows]


def _aware(moment: datetime) -> datetime:
    """SQLite returns naive datetimes for timezone-aware columns (they are UTC)."""
    return moment if moment.tzinfo else moment.replace(tzinfo=UTC)


@huey.task()
def run_job(key: str) -> None:
    execute(key)
