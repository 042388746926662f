"""One attempt at a job: which attempt this thread runs, the host that runs it, and the
actions it records.

Each claim records the host that took the job (``host``, "name:pid") and opens an entry in the
run's ``attempt_log``; a job records its actions there (``record_actions``) in the same unit of
work as the actions themselves, so a job retried after its worker was killed reports the
actions of every attempt (``actions`` summed, ``attempts`` one by one, in its result).
"""

from __future__ import annotations

import contextvars
import os
import socket
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import ColumnElement, select, update
from sqlalchemy.orm import Session

from backend.config import get_settings
from backend.db import session_scope
from backend.jobs.models import Job


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


# The attempt the current thread is running (a checkpoint checks that it still holds its job).
current_attempt: contextvars.ContextVar[Attempt | None] = contextvars.ContextVar(
    "dexlabel_job_attempt", default=None)


def host_id() -> str:
    """This process as the job table names it: "name:pid", the name DEXLABEL_HOST_NAME or the
    machine's hostname."""
    return f"{get_settings().host_name or socket.gethostname()}:{os.getpid()}"


def record_actions(session: Session, counts: Mapping[str, int]) -> None:
    """Add ``counts`` ({"approved": 1}) to the actions of the attempt this thread runs, in
    ``session``: the unit of work that holds the actions themselves, so they are recorded
    exactly when they commit. Nothing outside a job or for an attempt that lost its job."""
    attempt = current_attempt.get()
    if attempt is None or not counts:
        return
    session.flush()  # the unit of work's own writes first
    entries = session.scalar(select(Job.attempt_log).where(attempt.held()))
    if not entries:
        return
    entries = list(entries)
    last = dict(entries[-1])
    actions = dict(last.get("actions") or {})
    for what, n in counts.items():
        actions[what] = actions.get(what, 0) + n
    entries[-1] = {**last, "actions": actions}
    session.execute(update(Job).where(attempt.held()).values(attempt_log=entries)
                    .execution_options(synchronize_session=False))


def run_actions() -> dict[str, int]:
    """The actions every attempt of the current run of this thread's job recorded, summed
    (empty outside a job)."""
    attempt = current_attempt.get()
    if attempt is None:
        return {}
    with session_scope() as session:
        entries = session.scalar(select(Job.attempt_log).where(Job.key == attempt.key))
    return _summed(entries or [])


def _summed(entries: list[dict[str, Any]]) -> dict[str, int]:
    total: dict[str, int] = {}
    for entry in entries:
        for what, n in (entry.get("actions") or {}).items():
            total[what] = total.get(what, 0) + int(n)
    return total


def with_every_attempt(attempt: Attempt, result: dict[str, Any]) -> dict[str, Any]:
    """A finished job's result with the actions of all its run's attempts (when any were
    recorded): ``actions`` summed, and ``attempts`` one by one when there were several."""
    with session_scope() as session:
        entries = session.scalar(select(Job.attempt_log).where(attempt.held())) or []
    if not any(entry.get("actions") for entry in entries):
        return result
    result = {**result, "actions": _summed(entries)}
    if len(entries) > 1:
        result["attempts"] = [{"attempt": e.get("attempt"), "host": e.get("host"),
                               "actions": e.get("actions") or {}} for e in entries]
    return result
