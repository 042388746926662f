"""Queue jobs: enqueue by key, claim with a lease, finish or retry with backoff, reap the dead.

Every state change is one short committed statement, guarded by a compare-and-set on the
status (and on the attempt when renewing or finishing), so two consumers never run the same
attempt and a worker declared dead cannot overwrite the attempt that replaced it. The job's own
work runs in its own units of work between the claim and the finish, while a heartbeat renews
the attempt's lease; an attempt that lost its job anyway (its heartbeat could not reach the
database for a whole lease) stops at its next checkpoint without acting (``LeaseLost``).

A message the queue could not take (the queue was down) is recorded on the job's row, and the
reaper, which runs every minute in every consumer, sends it again once the queue answers.
"""

from __future__ import annotations

import contextvars
import importlib
import logging
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any, TypeVar, cast

from sqlalchemy import ColumnElement, CursorResult, Result, func, or_, select, update
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


class RetryLater(RuntimeError):
    """Raised by a job that must wait for something outside (the marketplace has not
    recorded a submission yet): recorded and retried like any failure, logged in one line."""


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
    if job.status in _ACTIVE:
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
    now = _now()
    made = session.execute(
        insert(Job).values(kind=kind, key=key, args=args or {}, status=status, attempts=0,
                           max_attempts=get_settings().job_max_attempts,
                           requests=1 if status == "queued" else 0, requests_claimed=0,
                           error=error, created_at=now, updated_at=now)
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
    if job.status in _ACTIVE:
        raise Conflict(f"job {job_id} is already {job.status}", state=job.status)
    return enqueue_job(session, job.kind, job.key, job.args)


def _rowcount(result: Result[Any]) -> int:
    """The rows an UPDATE changed (its result is a cursor result, which has a rowcount)."""
    return cast(CursorResult[Any], result).rowcount


# --- sending: the queue carries only the key -------------------------------------------------


def send(key: str, delay: float | None = None) -> bool:
    """Put the job's message on the queue (to run after ``delay`` seconds); True when sent.

    A queue that cannot take it (Redis down) is not the caller's failure: the job's row is
    marked unsent (``lease_until`` on a queued or retrying row is when its message is due) and
    the reaper sends it again within a minute of the queue answering.
    """
    try:
        if delay:
            run_job.schedule((key,), delay=delay)
        else:
            run_job(key)
        return True
    except Exception as exc:  # any queue failure: the row keeps the job
        log.warning("job %s: the queue did not take its message (%s); it is sent again once "
                    "the queue answers", key, _one_line(exc))
        _mark_unsent([key], _now() + timedelta(seconds=delay or 0))
        return False


def _mark_unsent(keys: list[str], due: datetime) -> None:
    if not keys:
        return
    try:
        with session_scope() as session:
            session.execute(update(Job).where(Job.key.in_(keys), Job.status.in_(_CLAIMABLE))
                            .values(lease_until=due)
                            .execution_options(synchronize_session=False))
    except Exception as exc:  # the database is down too: the reaper's slower pass finds it
        log.warning("could not record jobs %s as unsent: %s", ", ".join(keys), _one_line(exc))


def _one_line(exc: BaseException) -> str:
    return "".join(traceback.format_exception_only(type(exc), exc)).strip().splitlines()[-1]


# --- running: claim, lease, checkpoints, finish ----------------------------------------------


class LeaseLost(Exception):
    """This attempt no longer holds its job: its lease ran out and another attempt claimed the
    job. It stops where it is, acting no further; the attempt holding the job carries on."""


@dataclass(frozen=True)
class Attempt:
    """One claimed run of a job: its key, its number and when it was claimed (as stored), which
    together tell it from every other attempt, a later one of the same number included."""

    key: str
    number: int
    started_at: datetime
    lease_s: float

    def held(self) -> ColumnElement[bool]:
        """The row still belongs to this attempt."""
        return ((Job.key == self.key) & (Job.status == "running")
                & (Job.attempts == self.number) & (Job.started_at == self.started_at))


# The attempt the current thread is running (checkpoint() checks that it still holds its job).
_current: contextvars.ContextVar[Attempt | None] = contextvars.ContextVar(
    "dexlabel_job_attempt", default=None)


def _claim(key: str) -> tuple[Attempt, str, dict[str, Any]] | None:
    """Take the job for this worker: (attempt, kind, args), or None when not ours to run."""
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
        assert job.started_at is not None
        attempt = Attempt(key, job.attempts, job.started_at, lease)
        return attempt, job.kind, dict(job.args or {})


def _renew(attempt: Attempt) -> bool:
    """Extend the attempt's lease by a whole lease from now; False when it lost the job."""
    with session_scope() as session:
        renewed = session.execute(
            update(Job).where(attempt.held())
            .values(lease_until=_now() + timedelta(seconds=attempt.lease_s))
            .execution_options(synchronize_session=False))
        return _rowcount(renewed) == 1


class _Heartbeat:
    """Renews an attempt's lease every third of the lease while the job works, so a job that
    runs longer than its lease keeps it; stops when the attempt ends or loses its job. A
    worker that dies stops renewing, and its lease runs out."""

    def __init__(self, attempt: Attempt) -> None:
        self._attempt = attempt
        self._stopped = threading.Event()
        self._thread = threading.Thread(target=self._beat, name=f"lease:{attempt.key}",
                                        daemon=True)

    def __enter__(self) -> _Heartbeat:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._stopped.set()
        # A renewal stuck on an unanswering database must not hold the attempt's end up; a
        # late one changes nothing once the attempt has ended (it renews only a held job).
        self._thread.join(timeout=10)

    def _beat(self) -> None:
        interval = self._attempt.lease_s / 3
        while not self._stopped.wait(interval):
            try:
                if not _renew(self._attempt):
                    log.warning("job %s attempt %d: lost its lease to another attempt",
                                self._attempt.key, self._attempt.number)
                    return
            except Exception as exc:  # the database did not answer: try again next beat
                log.warning("job %s attempt %d: could not renew its lease: %s",
                            self._attempt.key, self._attempt.number, _one_line(exc))


def check_lease() -> None:
    """Raise LeaseLost unless the attempt this thread runs still holds its job (nothing to
    check outside a job). A job calls it before each action it must not repeat."""
    attempt = _current.get()
    if attempt is None:
        return
    with session_scope() as session:
        held = session.scalar(select(Job.id).where(attempt.held()))
    if held is None:
        raise LeaseLost(f"job {attempt.key} attempt {attempt.number} no longer holds the job")


def current_job_id() -> int:
    """The id of the job this thread runs (its row); LookupError outside a job."""
    attempt = _current.get()
    if attempt is None:
        raise LookupError("not inside a job")
    with session_scope() as session:
        job_id = session.scalar(select(Job.id).where(Job.key == attempt.key))
    if job_id is None:
        raise LookupError(f"job {attempt.key} has no row")
    return int(job_id)


def report_progress(done: int, total: int, stage: str = "") -> None:
    """Record how far the job this thread runs has come (one short committed UPDATE); a call
    outside a job, or from an attempt that lost its job, records nothing."""
    attempt = _current.get()
    if attempt is None:
        return
    with session_scope() as session:
        session.execute(update(Job).where(attempt.held())
                        .values(progress={"done": done, "total": total, "stage": stage})
                        .execution_options(synchronize_session=False))


def checkpoint() -> None:
    """A point between a job's actions: a crash drill may kill the worker here (it pauses
    job_pause_s), and an attempt that no longer holds its job stops here (LeaseLost)."""
    pause = get_settings().job_pause_s
    if pause:
        time.sleep(pause)
    check_lease()


def _finish(attempt: Attempt, **values: Any) -> bool:
    """End ``attempt`` with ``values`` (compare-and-set); False when it was not ours.

    A job that ends done or failed while asks arrived after its attempt started is queued
    again at once, so work submitted during a run is never left unprocessed.
    """
    key = attempt.key
    rerun = False
    with session_scope() as session:
        done = session.execute(
            update(Job).where(attempt.held())
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
        send(key)
    return True


def _retry_delay(attempt: int) -> float:
    base = get_settings().job_retry_base_s
    return min(base * 2 ** (attempt - 1), 3600.0)


def execute(key: str) -> None:
    """Run one attempt of the job ``key`` (the body of the queue task)."""
    claim = _claim(key)
    if claim is None:
        return
    attempt, kind, args = claim
    handler = handler_for(kind)
    failure: Exception | None = None
    result: dict[str, Any] = {}
    token = _current.set(attempt)
    try:
        with _Heartbeat(attempt):
            if handler is None:
                raise RuntimeError(f"no handler for jobs of kind {kind!r} in this worker")
            result = handler.run(args) or {}
    except LeaseLost:
        log.warning("job %s attempt %d lost its lease to a newer attempt: stopped without "
                    "acting further", key, attempt.number)
        return
    except RetryLater as exc:  # an expected wait: one line, no traceback
        log.info("job %s attempt %d: %s; it runs again later", key, attempt.number, exc)
        failure = exc
    except Exception as exc:  # every failure is recorded on the job, then retried or failed
        log.exception("job %s attempt %d failed", key, attempt.number)
        failure = exc
    finally:
        _current.reset(token)
    if failure is not None:
        _after_failure(attempt, failure)
        return
    _finish(attempt, status="done", result=result, finished_at=_now())


def _after_failure(attempt: Attempt, exc: Exception) -> None:
    # "ValueError: boom" (the exception's type and message, as a traceback's last line).
    error = "".join(traceback.format_exception_only(type(exc), exc)).strip()
    with session_scope() as session:
        job = session.scalar(select(Job).where(Job.key == attempt.key))
        final = job is None or attempt.number >= job.max_attempts
    if final:
        _finish(attempt, status="failed", error=error, finished_at=_now())
        return
    if _finish(attempt, status="retrying", error=error):
        send(attempt.key, delay=_retry_delay(attempt.number))


# --- the reaper ------------------------------------------------------------------------------


def requeue_stale(now: datetime | None = None, starting: bool = False,
                  queue_reset: bool = False) -> list[str]:
    """Queue again the jobs whose worker died (lease ran out) or whose message was lost.

    A message known lost (the queue did not take it, see ``send``) is sent at its due time; one
    that vanished unnoticed is sent again after job_requeue_after_s. A consumer ``starting``
    also re-sends every queued job at once: its message may have gone to a queue no consumer
    reads (a command run with other queue settings) or been lost while none ran. After a
    ``queue_reset`` (the queue's store lost what it held, see backend.queue) every queued job
    is sent again at once and every retrying one at its retry time. A duplicate message is
    harmless, the claim runs a job once.
    """
    settings = get_settings()
    now = now or _now()
    lost_before = now - timedelta(seconds=settings.job_requeue_after_s)
    with session_scope() as session:
        stale: list[ColumnElement[bool]] = [
            (Job.status == "running") & (Job.lease_until < now),
            Job.status.in_(_CLAIMABLE) & (Job.lease_until <= now),
            Job.status.in_(_CLAIMABLE) & (Job.updated_at < lost_before)]
        if starting:
            stale.append(Job.status == "queued")
        if queue_reset:
            stale.append(Job.status.in_(_CLAIMABLE))
        rows = session.execute(select(Job.key, Job.status, Job.updated_at, Job.lease_until,
                                      Job.attempts).where(or_(*stale))).all()
        for key, *_ in rows:
            # Touch the row so a lost message is re-sent once per interval, not every minute,
            # and clear its unsent mark (a send that fails again sets it again).
            session.execute(update(Job).where(Job.key == key, Job.status.in_(_CLAIMABLE))
                            .values(updated_at=now, lease_until=None)
                            .execution_options(synchronize_session=False))
    for n, (key, status, updated_at, lease_until, attempts) in enumerate(rows):
        delay = None
        if status == "running":
            log.warning("job %s: its worker stopped before the lease ran out; queued again", key)
        elif lease_until is not None and lease_until <= now:
            log.warning("job %s: the queue did not take its message; sent again", key)
        elif updated_at < lost_before:
            log.warning("job %s: queued for over %.0f s with no worker taking it; its message "
                        "is sent again", key, settings.job_requeue_after_s)
        elif queue_reset:
            if starting:  # a new queue, or one emptied while no worker ran: routine here
                log.info("job %s: sent to this worker as it starts", key)
            else:
                log.warning("job %s: the queue lost its messages; sent again", key)
            if status == "retrying":  # at the time its retry was due
                due = updated_at + timedelta(seconds=_retry_delay(attempts))
                delay = max((due - now).total_seconds(), 0.0)
        else:  # queued recently, before this consumer started: routine, not a fault
            log.info("job %s: queued before this worker started; sent to it", key)
        if not send(key, delay=delay):
            # The queue is down: the rest are marked unsent at once rather than each waiting
            # for the queue to refuse it.
            _mark_unsent([k for k, *_ in rows[n + 1:]], now)
            break
    return [key for key, *_ in rows]



@huey.task()
def run_job(key: str) -> None:
    execute(key)
