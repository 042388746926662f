"""The queue consumers (a worker process's threads, or the embedded deployment's in-process
ones) and the reaper every consumer runs each minute: jobs whose worker died or whose message
was lost are sent again. Also ``run_queued``: every queued job run here, in order (what an idle
queue comes to), for commands and tests that run their jobs in their own process.
"""

from __future__ import annotations

import logging
from datetime import datetime, timedelta
from typing import Any

from huey import crontab
from huey.consumer import Consumer
from sqlalchemy import ColumnElement, or_, select, update

from backend.config import get_settings
from backend.db import session_scope
from backend.jobs.models import Job
from backend.jobs.runner import CLAIMABLE, execute, mark_unsent, retry_delay, send, utc_now
from backend.queue import QUEUE_RETRY_MAX_S, huey, queue_lost_messages

log = logging.getLogger(__name__)


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
    now = now or utc_now()
    lost_before = now - timedelta(seconds=get_settings().job_requeue_after_s)
    rows = _stale_rows(now, lost_before, starting, queue_reset)
    for n, row in enumerate(rows):
        delay = _why_again(row, now, lost_before, starting, queue_reset)
        if not send(row.key, delay=delay):
            # The queue is down: the rest are marked unsent at once rather than each waiting
            # for the queue to refuse it.
            mark_unsent([r.key for r in rows[n + 1:]], now)
            break
    return [row.key for row in rows]


def _stale_rows(now: datetime, lost_before: datetime, starting: bool,
                queue_reset: bool) -> list[Any]:
    """The rows of the jobs to send again (key, status, updated_at, lease_until, attempts),
    each touched so a lost message is re-sent once per interval, not every minute, and its
    unsent mark cleared (a send that fails again sets it again)."""
    with session_scope() as session:
        stale: list[ColumnElement[bool]] = [
            (Job.status == "running") & (Job.lease_until < now),
            Job.status.in_(CLAIMABLE) & (Job.lease_until <= now),
            Job.status.in_(CLAIMABLE) & (Job.updated_at < lost_before)]
        if starting:
            stale.append(Job.status == "queued")
        if queue_reset:
            stale.append(Job.status.in_(CLAIMABLE))
        rows = list(session.execute(select(Job.key, Job.status, Job.updated_at,
                                           Job.lease_until, Job.attempts).where(or_(*stale))))
        for row in rows:
            session.execute(update(Job).where(Job.key == row.key, Job.status.in_(CLAIMABLE))
                            .values(updated_at=now, lease_until=None)
                            .execution_options(synchronize_session=False))
    return rows


def _why_again(row: Any, now: datetime, lost_before: datetime, starting: bool,
               queue_reset: bool) -> float | None:
    """Log why a stale job is sent again; the delay to send it with (None: at once)."""
    key = row.key
    if row.status == "running":
        log.warning("job %s: its worker stopped before the lease ran out; queued again", key)
    elif row.lease_until is not None and row.lease_until <= now:
        log.warning("job %s: the queue did not take its message; sent again", key)
    elif row.updated_at < lost_before:
        log.warning("job %s: queued for over %.0f s with no worker taking it; its message "
                    "is sent again", key, get_settings().job_requeue_after_s)
    elif queue_reset:
        if starting:  # a new queue, or one emptied while no worker ran: routine here
            log.info("job %s: sent to this worker as it starts", key)
        else:
            log.warning("job %s: the queue lost its messages; sent again", key)
        if row.status == "retrying":  # at the time its retry was due
            due = row.updated_at + timedelta(seconds=retry_delay(row.attempts))
            return max((due - now).total_seconds(), 0.0)
    else:  # queued recently, before this consumer started: routine, not a fault
        log.info("job %s: queued before this worker started; sent to it", key)
    return None


# Seconds between reaper passes: huey's periodic tasks run at most once a minute, so each
# minute's pass schedules a second one this much later. With the minute's lease, a killed
# worker's job is queued again within lease + REAP_EVERY_S of its last heartbeat.
REAP_EVERY_S = 30.0


@huey.periodic_task(crontab(minute="*"))
def reap_jobs() -> None:
    """Every minute: re-queue jobs whose worker died or whose queue message was lost (all of
    them at once when the queue's store lost its messages, e.g. a Redis restarted empty),
    and again half a minute later."""
    requeue_stale(queue_reset=queue_lost_messages())
    try:
        reap_jobs_again.schedule(delay=REAP_EVERY_S)
    except Exception as exc:  # the queue is down: the next minute's pass comes anyway
        log.warning("could not schedule the reaper's next pass: %s", exc)


@huey.task()
def reap_jobs_again() -> None:
    """The half-minute pass of the reaper (jobs whose worker died or whose message was lost)."""
    requeue_stale()


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
