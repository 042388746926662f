"""Running queued jobs: the handler registry; claim with a lease, finish or retry with
backoff (the reaper and the queue consumers are backend.jobs.consumer's).

Every state change is one short committed statement, guarded by a compare-and-set on the
status (and on the attempt when renewing or finishing), so two consumers never run the same
attempt and a worker declared dead cannot overwrite the attempt that replaced it. The job's own
work runs in its own units of work between the claim and the finish, while a heartbeat renews
the attempt's lease; an attempt that lost its job anyway (its heartbeat could not reach the
database for a whole lease) stops at its next checkpoint without acting (``LeaseLost``).

A message the queue could not take (the queue was down) is recorded on the job's row, and the
reaper sends it again once the queue answers.

Each claim records the host that took the job and opens an entry in the run's attempt log, where
the job records its actions (backend.jobs.attempts).
"""

from __future__ import annotations

import logging
import threading
import time
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any, TypeVar, cast

from sqlalchemy import CursorResult, Result, or_, select, update

from backend.config import get_settings
from backend.db import session_scope
from backend.jobs.attempts import (
    Attempt,
    current_attempt,
    host_id,
    with_every_attempt,
)
from backend.jobs.models import Job
from backend.queue import huey

log = logging.getLogger(__name__)

CLAIMABLE = ("queued", "retrying")
ACTIVE = ("queued", "running", "retrying")
# The heartbeat renews a lease this fraction of it apart.
HEARTBEAT_FRACTION = 0.25


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
                    "the queue answers", key, one_line(exc))
        mark_unsent([key], utc_now() + timedelta(seconds=delay or 0))
        return False


def mark_unsent(keys: list[str], due: datetime) -> None:
    if not keys:
        return
    try:
        with session_scope() as session:
            session.execute(update(Job).where(Job.key.in_(keys), Job.status.in_(CLAIMABLE))
                            .values(lease_until=due)
                            .execution_options(synchronize_session=False))
    except Exception as exc:  # the database is down too: the reaper's slower pass finds it
        log.warning("could not record jobs %s as unsent: %s", ", ".join(keys), one_line(exc))


def one_line(exc: BaseException) -> str:
    return "".join(traceback.format_exception_only(type(exc), exc)).strip().splitlines()[-1]


# --- running: claim, lease, checkpoints, finish ----------------------------------------------


class LeaseLost(Exception):
    """This attempt no longer holds its job: its lease ran out and another attempt claimed the
    job. It stops where it is, acting no further; the attempt holding the job carries on."""


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
        host = host_id()
        claimed = session.execute(
            update(Job).where(Job.key == key, or_(
                Job.status.in_(CLAIMABLE),
                (Job.status == "running") & (Job.lease_until < now)))
            .values(status="running", attempts=Job.attempts + 1, started_at=now,
                    lease_until=now + timedelta(seconds=lease), error=None,
                    requests_claimed=Job.requests, host=host)
            .execution_options(synchronize_session=False))
        if _rowcount(claimed) != 1:
            return None
        session.refresh(job)
        assert job.started_at is not None
        # The claim holds the row's write lock: the log is read and extended in one step. A
        # run's first attempt starts a new log.
        earlier = list(job.attempt_log or []) if job.attempts > 1 else []
        job.attempt_log = [*earlier, {"attempt": job.attempts, "host": host,
                                      "started_at": now.isoformat(timespec="seconds")}]
        attempt = Attempt(key, job.attempts, job.started_at, lease)
        kind, args = job.kind, dict(job.args or {})
    log.info("job %s attempt %d runs on %s", key, attempt.number, host)
    return attempt, kind, args


def _renew(attempt: Attempt) -> bool:
    """Extend the attempt's lease by a whole lease from now; False when it lost the job."""
    with session_scope() as session:
        renewed = session.execute(
            update(Job).where(attempt.held())
            .values(lease_until=utc_now() + timedelta(seconds=attempt.lease_s))
            .execution_options(synchronize_session=False))
        return _rowcount(renewed) == 1


class _Heartbeat:
    """Renews an attempt's lease every quarter of the lease while the job works, so a job that
    runs longer than its lease keeps it (and a renewal or two may fail on a database that
    does not answer); stops when the attempt ends or loses its job. A worker that dies stops
    renewing, and its lease runs out. The beat is a thread of its own: a long handler (the
    solve, in PyTorch and NumPy calls that release the interpreter lock) needs no calls of
    its own to keep its lease."""

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
        interval = self._attempt.lease_s * HEARTBEAT_FRACTION
        while not self._stopped.wait(interval):
            try:
                if not _renew(self._attempt):
                    log.warning("job %s attempt %d: lost its lease to another attempt",
                                self._attempt.key, self._attempt.number)
                    return
            except Exception as exc:  # the database did not answer: try again next beat
                log.warning("job %s attempt %d: could not renew its lease: %s",
                            self._attempt.key, self._attempt.number, one_line(exc))


def check_lease() -> None:
    """Raise LeaseLost unless the attempt this thread runs still holds its job (nothing to
    check outside a job). A job calls it before each action it must not repeat."""
    attempt = current_attempt.get()
    if attempt is None:
        return
    with session_scope() as session:
        held = session.scalar(select(Job.id).where(attempt.held()))
    if held is None:
        raise LeaseLost(f"job {attempt.key} attempt {attempt.number} no longer holds the job")


def current_job_id() -> int:
    """The id of the job this thread runs (its row); LookupError outside a job."""
    attempt = current_attempt.get()
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
    attempt = current_attempt.get()
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


def retry_delay(attempt: int) -> float:
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
    token = current_attempt.set(attempt)
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
        current_attempt.reset(token)
    if failure is not None:
        _after_failure(attempt, failure)
        return
    _finish(attempt, status="done", result=with_every_attempt(attempt, result),
            finished_at=utc_now())


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
        send(attempt.key, delay=retry_delay(attempt.number))


@huey.task()
def run_job(key: str) -> None:
    execute(key)
