"""The job API: enqueue by key (once the unit of work commits), list, describe, retry.

A job is a row of the job table; the queue carries only its key. Running a job (claiming it
with a lease, the heartbeat, retries, the reaper) is backend.jobs.runner's; the handlers that
do each kind's work are registered there by the commands that run jobs.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select, update
from sqlalchemy.dialects.postgresql import insert as pg_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.orm import Session

from backend.config import get_settings
from backend.errors import Conflict, NotFound
from backend.jobs.models import Job
from backend.jobs.runner import ACTIVE, send, utc_now
from backend.queue import enqueue_after_commit


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


def count_jobs(session: Session) -> dict[str, dict[str, int]]:
    """Jobs per kind and status (kinds and statuses without a job left out)."""
    out: dict[str, dict[str, int]] = {}
    for kind, status, n in session.execute(select(Job.kind, Job.status, func.count())
                                           .group_by(Job.kind, Job.status)
                                           .order_by(Job.kind, Job.status)):
        out.setdefault(kind, {})[status] = int(n)
    return out


def enqueue_job(session: Session, kind: str, key: str, args: dict[str, Any] | None = None) -> Job:
    """Queue the job named ``key`` once this unit of work commits.

    Every ask is counted on the job's row. A job already queued (or waiting to retry) will see
    the newest data when it starts; a running one started before this unit of work's data, so
    it is queued again when its attempt ends (``_finish``). A finished, failed or waiting job
    is queued again with fresh attempts.
    """
    if _insert_new(session, kind, key, args, "queued"):
        enqueue_after_commit(session, send, key)
        return session.scalars(select(Job).where(Job.key == key)).one()
    job = session.scalars(select(Job).where(Job.key == key)).one()
    # Counting the ask takes the row's write lock, so the status read next is the one a
    # finishing attempt will see this ask against (see _finish).
    session.execute(update(Job).where(Job.key == key).values(requests=Job.requests + 1)
                    .execution_options(synchronize_session=False))
    session.refresh(job)
    if job.status in ACTIVE:
        return job
    job.status, job.attempts, job.error, job.args = "queued", 0, None, args or job.args
    job.finished_at = None
    session.flush()
    enqueue_after_commit(session, send, key)
    return job


def _insert_new(session: Session, kind: str, key: str, args: dict[str, Any] | None,
                status: str, error: str | None = None) -> bool:
    """Insert the job's row unless the key exists (also when a concurrent unit of work inserts
    it first: the insert then waits for that one and does nothing); True when this call made
    it."""
    insert = pg_insert if session.get_bind().dialect.name == "postgresql" else sqlite_insert
    at = utc_now()
    made = session.execute(
        insert(Job).values(kind=kind, key=key, args=args or {}, status=status, attempts=0,
                           max_attempts=get_settings().job_max_attempts,
                           requests=1 if status == "queued" else 0, requests_claimed=0,
                           error=error, created_at=at, updated_at=at)
        .on_conflict_do_nothing(index_elements=["key"]).returning(Job.id))
    return made.scalar_one_or_none() is not None


def mark_waiting(session: Session, kind: str, key: str, args: dict[str, Any], reason: str) -> Job:
    """Record a job that cannot run yet (e.g. no solver installed), with the reason shown."""
    if not _insert_new(session, kind, key, args, "waiting", reason):
        session.execute(update(Job).where(Job.key == key).values(status="waiting", error=reason)
                        .execution_options(synchronize_session=False))
    job = session.scalars(select(Job).where(Job.key == key)).one()
    session.refresh(job)
    return job


def retry_job(session: Session, job_id: int) -> Job:
    """An admin's re-run of a failed or waiting job."""
    job = get_job_or_raise(session, job_id)
    if job.status in ACTIVE:
        raise Conflict(f"job {job_id} is already {job.status}", state=job.status)
    return enqueue_job(session, job.kind, job.key, job.args)


def last_error_line(job: Job) -> str:
    """The last line of a failed job's error (the exception's message), for a reason shown to
    a person; "unknown error" when it has none."""
    lines = (job.error or "").strip().splitlines()
    return lines[-1] if lines else "unknown error"
