"""Running queued jobs: the handler registry; claim with a lease, finish or retry with
backoff; reap the dead; the queue consumers.

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
import logging
import threading
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any, TypeVar, cast

from huey import crontab
from huey.consumer import Consumer
from sqlalchemy import ColumnElement, CursorResult, Result, or_, select, update

from backend.config import get_settings
from backend.db import session_scope
from backend.jobs.models import Job
from backend.queue import QUEUE_RETRY_MAX_S, huey, queue_lost_messages

log = logging.getLogger(__name__)

CLAIMABLE = ("queued", "retrying")
ACTIVE = ("queued", "running", "retrying")


@dataclass(frozen=True)
class Handler:
    run: Callable[[dict[str, Any]], dict[str, Any] | None]
    lease_s: float | None


class RetryLater(RuntimeError):
    """Raised by a job that must wait for something outside (the marketplace has not
    recorded a submission yet): recorded and retried like any failure, logged in one line."""


_HANDLERS: dict[str, Handler] = {}


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


def register_handlers(handlers: Mapping[str, Handler]) -> None:
    """Register each kind's handler in this process (a command that runs jobs does it once,
    before it runs any: the queue consumer, ``--now``/``--wait`` commands, the tests)."""
    _HANDLERS.update(handlers)


def handler_for(kind: str) -> Handler | None:
    return _HANDLERS.get(kind)



def utc_now() -> datetime:
    return datetime.now(UTC)


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
        _mark_unsent([key], utc_now() + timedelta(seconds=delay or 0))
        return False


def _mark_unsent(keys: list[str], due: datetime) -> None:
    if not keys:
        return
    try:
        with session_scope() as session:
            session.execute(update(Job).where(Job.key.in_(keys), Job.status.in_(CLAIMABLE))
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
        now = utc_now()
        claimed = session.execute(
            update(Job).where(Job.key == key, or_(
                Job.status.in_(CLAIMABLE),
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
            .values(lease_until=utc_now() + timedelta(seconds=attempt.lease_s))
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
    _finish(attempt, status="done", result=result, finished_at=utc_now())


def _after_failure(attempt: Attempt, exc: Exception) -> None:
    # "ValueError: boom" (the exception's type and message, as a traceback's last line).
    error = "".join(traceback.format_exception_only(type(exc), exc)).strip()
    with session_scope() as session:
        job = session.scalar(select(Job).where(Job.key == attempt.key))
        final = job is None or attempt.number >= job.max_attempts
    if final:
        _finish(attempt, status="failed", error=error, finished_at=utc_now())
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
    now = now or utc_now()
    lost_before = now - timedelta(seconds=settings.job_requeue_after_s)
    with session_scope() as session:
        stale: list[ColumnElement[bool]] = [
            (Job.status == "running") & (Job.lease_until < now),
            Job.status.in_(CLAIMABLE) & (Job.lease_until <= now),
            Job.status.in_(CLAIMABLE) & (Job.updated_at < lost_before)]
        if starting:
            stale.append(Job.status == "queued")
        if queue_reset:
            stale.append(Job.status.in_(CLAIMABLE))
        rows = session.execute(select(Job.key, Job.status, Job.updated_at, Job.lease_until,
                                      Job.attempts).where(or_(*stale))).all()
        for key, *_ in rows:
            # Touch the row so a lost message is re-sent once per interval, not every minute,
            # and clear its unsent mark (a send that fails again sets it again).
            session.execute(update(Job).where(Job.key == key, Job.status.in_(CLAIMABLE))
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


# --- consumers -------------------------------------------------------------------------------


@huey.periodic_task(crontab(minute="*"))
def reap_jobs() -> None:
    """Every minute: re-queue jobs whose worker died or whose queue message was lost (all of
    them at once when the queue's store lost its messages, e.g. a Redis restarted empty)."""
    requeue_stale(queue_reset=queue_lost_messages())


def run_queued(max_rounds: int = 200) -> list[str]:
    """Run here, one after another, every job queued or waiting to retry, and the jobs they
    queue, until none is left (what an idle queue comes to); the keys run, in order.
    RuntimeError naming the last keys when the queue is still not idle after ``max_rounds``
    passes."""
    ran: list[str] = []
    for _ in range(max_rounds):
        with session_scope() as session:
            keys = list(session.scalars(select(Job.key).where(Job.status.in_(CLAIMABLE))
                                        .order_by(Job.id)))
        if not keys:
            return ran
        for key in keys:
            execute(key)
            ran.append(key)
    raise RuntimeError(f"the job queue never went idle: {ran[-10:]}")


def make_consumer(workers: int) -> Consumer:
    """A queue consumer for this process (its threads not started yet), after sending again
    the jobs that lost their worker or message while none ran. The job handlers must be
    registered first (register_handlers)."""
    try:
        reset = queue_lost_messages()
    except Exception:
        log.exception("the queue does not answer; jobs are sent once it does")
        reset = True
    try:  # queued jobs, and jobs whose worker died while no consumer ran, are picked up at once
        requeue_stale(starting=True, queue_reset=reset)
    except Exception:
        log.exception("could not check the job table for stale jobs")
    # periodic: the reaper (reap_jobs, below) runs every minute in every consumer.
    # max_delay: a worker thread that cannot read the queue (Redis down) tries again at least
    # every QUEUE_RETRY_MAX_S, so it takes work within seconds of the queue coming back.
    return huey.create_consumer(workers=workers, worker_type="thread", periodic=True,
                                max_delay=QUEUE_RETRY_MAX_S)


def start_inprocess_consumer(workers: int) -> Consumer:
    """Start a consumer in background threads of this process (the embedded deployment)."""
    consumer = make_consumer(workers)
    consumer.start()  # spawns the scheduler and worker threads, then returns
    log.info("in-process queue consumer started with %d workers", workers)
    return consumer
