"""Queue jobs as the admins see them: one row per job key, with status, attempts and error.

The queue (Huey) carries only the key; this row is the truth. A job is claimed by a
compare-and-set on its status, holds a lease while it runs, and a job whose lease ran out (its
worker was killed) is queued again by the reaper, so every job ends ``done`` or ``failed``.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, CheckConstraint, Index, Integer, String, Text
from sqlalchemy.orm import Mapped, mapped_column

from backend.db import Base, TimestampMixin, UTCDateTime, one_of, utcnow

JOB_STATUSES = ("queued", "running", "retrying", "waiting", "done", "failed")


class Job(TimestampMixin, Base):
    __tablename__ = "jobs"
    __table_args__ = (
        # The job listing, newest first, of one status or one kind.
        Index("ix_jobs_status_id", "status", "id"),
        Index("ix_jobs_kind_id", "kind", "id"),
        one_of("status", ("queued", "running", "retrying", "waiting", "done", "failed")),
        CheckConstraint("attempts >= 0 AND max_attempts >= 1", name="attempts_valid"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    # What runs: "qc", "solve", ...; the key names the work ("qc:12:hand:0") and is unique.
    kind: Mapped[str] = mapped_column(String(32))
    key: Mapped[str] = mapped_column(String(128), unique=True)
    args: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    status: Mapped[str] = mapped_column(String(16), default="queued")
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    max_attempts: Mapped[int] = mapped_column(Integer, default=5)
    error: Mapped[str | None] = mapped_column(Text)
    result: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    # How far a job that reports progress has come: {"done", "total", "stage"}; None otherwise.
    progress: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    # Asks for this job so far, and the count its running attempt started from: a job asked
    # for again while it runs (new work arrived) is queued again when that attempt ends.
    requests: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    requests_claimed: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    # A running job: until when its attempt holds it (renewed by the attempt's heartbeat). A
    # queued or retrying job: when its queue message, which the queue did not take, is due to
    # be sent again by the reaper; None once sent.
    lease_until: Mapped[datetime | None] = mapped_column(UTCDateTime)
    # The host whose attempt last claimed the job ("name:pid", DEXLABEL_HOST_NAME or the
    # machine's hostname), and this run's attempts: [{"attempt", "host", "started_at",
    # "actions"}], so a job retried after its worker died still reports every attempt's actions.
    host: Mapped[str | None] = mapped_column(String(255))
    attempt_log: Mapped[list[dict[str, Any]] | None] = mapped_column(JSON)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow, onupdate=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
