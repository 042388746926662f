"""Quality control results: one report per scored assignment (training clips, the gold tasks,
are rows of backend.annotation.models).

A report is overwritten each time its target is scored again (more views came in); the action
taken on it (approve, reject, re-open) is recorded once and never repeated, so a re-run of a
QC job changes scores but never pays or rejects twice.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Boolean, Index, Integer, String, Text
from sqlalchemy.orm import Mapped, mapped_column

from backend.db import Base, TimestampMixin, UTCDateTime, one_of, parent_key, utcnow

# A report's action_detail where an admin approved or rejected the work, not QC: QC left it
# for review (a later scoring of the target may read approve on the same report).
ADMIN_DECIDED = "decided by an admin"


class QCReport(TimestampMixin, Base):
    __tablename__ = "qc_reports"
    __table_args__ = (
        # Each worker's tally by outcome (worker quality) is read from this index alone.
        Index("ix_qc_reports_worker_id_outcome", "worker_id", "outcome", "provisional"),
        one_of("outcome", ("approve", "review", "reject")),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    assignment_id: Mapped[int] = parent_key("assignments.id", unique=True)
    task_id: Mapped[int] = parent_key("tasks.id", index=True)
    sequence_id: Mapped[int] = parent_key("sequences.id", index=True)
    target_key: Mapped[str] = mapped_column(String(32))
    worker_id: Mapped[str] = mapped_column(String(64))
    # "consensus" (scored against the other views) or "gold" (a training clip's known labels).
    method: Mapped[str] = mapped_column(String(16), default="consensus")
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON)
    per_joint: Mapped[list[Any]] = mapped_column(JSON, default=list)
    per_frame: Mapped[list[Any]] = mapped_column(JSON, default=list)
    swaps: Mapped[list[Any]] = mapped_column(JSON, default=list)
    # What the reviewer's replay draws (backend.quality.admin_queue): the reference pixels the
    # label is judged against per frame and point, its error matrix, its issue spans. None on
    # reports written before it was stored (scoring the target again writes it).
    replay: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    thresholds: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    outcome: Mapped[str] = mapped_column(String(8))
    reasons: Mapped[list[str]] = mapped_column(JSON, default=list)
    feedback: Mapped[str] = mapped_column(Text, default="")
    provisional: Mapped[bool] = mapped_column(Boolean, default=False)
    views: Mapped[int] = mapped_column(Integer, default=0)
    # What was done about it, once: "approved", "rejected", "review" (left to an admin),
    # "waiting" (provisional), "recorded" (no marketplace submission to act on).
    action: Mapped[str | None] = mapped_column(String(16))
    action_detail: Mapped[str | None] = mapped_column(Text)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow, onupdate=utcnow)
