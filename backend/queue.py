"""The job queue: Huey on SQLite by default, on Redis when DEXLABEL_REDIS_URL is set.

Jobs are enqueued only after the unit of work that created their inputs has committed, and
they take ids, never ORM objects, so a consumer on another machine can run them.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from huey import Huey, RedisHuey
from huey.storage import SqliteStorage
from sqlalchemy import event
from sqlalchemy.orm import Session

from backend.config import Settings, get_settings

log = logging.getLogger(__name__)


class LazySqliteStorage:
    """Huey's SQLite storage, opened (and its file created) on first use rather than when
    this module is imported: a command that finds no instance leaves no file behind."""

    def __init__(self, name: str, filename: str, **kwargs: Any) -> None:
        self._name, self._filename, self._kwargs = name, filename, kwargs
        self._real: SqliteStorage | None = None
        self._lock = threading.Lock()

    def _storage(self) -> SqliteStorage:
        with self._lock:
            if self._real is None:
                Path(self._filename).parent.mkdir(parents=True, exist_ok=True)
                self._real = SqliteStorage(self._name, filename=self._filename, **self._kwargs)
            return self._real

    def __getattr__(self, attr: str) -> Any:
        return getattr(self._storage(), attr)


# Redis socket limits: a Redis that does not answer (down, or a host that drops packets) makes
# an enqueue fail within seconds instead of hanging the request or job that sends it. Reads
# block for at most a second (Huey's read timeout), well within the socket timeout.
REDIS_CONNECT_TIMEOUT_S = 5.0
REDIS_SOCKET_TIMEOUT_S = 10.0
# The longest a consumer's worker thread waits before reading the queue again after an empty
# read (the SQLite queue) or a failed one (Redis down).
QUEUE_RETRY_MAX_S = 5.0


def make_huey(settings: Settings) -> Huey:
    if settings.redis_url:
        from redis import ConnectionPool

        pool = ConnectionPool.from_url(settings.redis_url,
                                       socket_connect_timeout=REDIS_CONNECT_TIMEOUT_S,
                                       socket_timeout=REDIS_SOCKET_TIMEOUT_S)
        return RedisHuey("dexlabel", connection_pool=pool, results=False)
    return Huey("dexlabel", results=False, storage_class=LazySqliteStorage,
                filename=str(settings.queue_path))


huey: Huey = make_huey(get_settings())


def enqueue_after_commit(session: Session, task: Callable[..., Any], *args: Any) -> None:
    """Run ``task(*args)`` (a Huey task) once ``session`` commits; drop it on rollback."""
    pending: list[tuple[Callable[..., Any], tuple[Any, ...]]] = session.info.setdefault(
        "after_commit_jobs", []
    )
    pending.append((task, args))


@event.listens_for(Session, "after_commit")
def _flush_jobs(session: Session) -> None:
    # The data is committed by now; a queue that is down must not make the caller believe the
    # unit of work failed. A job's message goes through backend.jobs.service.send, which
    # records one the queue refused so the reaper sends it again; anything else is logged.
    for task, args in session.info.pop("after_commit_jobs", []):
        try:
            task(*args)
        except Exception:
            log.exception("could not enqueue %s%r after commit", getattr(task, "name", task), args)


@event.listens_for(Session, "after_rollback")
def _drop_jobs(session: Session) -> None:
    session.info.pop("after_commit_jobs", None)


# A mark the reaper leaves in the queue's own store: when it is gone, the store lost what it
# held (a Redis restarted without persistence, or flushed), messages included.
_MARK = "dexlabel.queue-mark"


def queue_lost_messages(queue: Huey | None = None) -> bool:
    """True when the queue's store no longer holds the mark left by the previous call (or was
    never marked): messages sent before may be gone. Leaves the mark in either case."""
    return bool((queue or huey).put_if_empty(_MARK, time.time()))


def check_queue(timeout_s: float = 2.0) -> str | None:
    """Why the queue cannot take messages now (None when it can): a Redis ping within
    ``timeout_s`` when Redis is the queue, else a read of the SQLite queue file."""
    settings = get_settings()
    try:
        if settings.redis_url:
            import redis

            client = redis.Redis.from_url(settings.redis_url, socket_timeout=timeout_s,
                                          socket_connect_timeout=timeout_s)
            try:
                client.ping()
            finally:
                client.close()
        else:
            huey.pending_count()
    except Exception as exc:  # any failure to reach it is the answer
        return f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc) else ''}"
    return None
