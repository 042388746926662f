"""Solve runs: one row per request to fit a sequence's hand and object poses.

The per-frame outputs (poses, joints, residuals) live in storage as one npz under the run's
``result_key``; the row keeps what admins list and compare: parameters, status, timings and a
summary of the residuals. A sequence's current result is its newest run that finished
(``done``), so a new run that is queued, running or failed never hides the previous one.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Integer, String, Text
from sqlalchemy.orm import Mapped, mapped_column

from backend.db import Base, TimestampMixin, UTCDateTime, one_of, parent_key

SOLVE_STATUSES = ("queued", "running", "done", "failed")


class SolveRun(TimestampMixin, Base):
    __tablename__ = "solve_runs"
    __table_args__ = (
        one_of("status", ("queued", "running", "done", "failed")),
        one_of("optimiser", ("paper", "default")),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    sequence_id: Mapped[int] = parent_key("sequences.id", index=True)
    optimiser: Mapped[str] = mapped_column(String(16))
    # The solver settings used (weights, iterations, device), as given to worker.solver.
    params: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    status: Mapped[str] = mapped_column(String(16), default="queued", index=True)
    # Seconds per stage: gather (DB and storage reads), the solver's own stages, store.
    timings: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    # Residuals (MPJPE is unknown on real data): fingertip px per finger, depth RMS mm, counts.
    summary: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    error: Mapped[str | None] = mapped_column(Text)
    # Storage key of the per-frame outputs (npz), set when the run is done.
    result_key: Mapped[str | None] = mapped_column(String(500))
    # Digest of the accepted assignments the pipeline requested this run for (None: asked
    # for by hand); one automatic run per set of accepted labels.
    labels_digest: Mapped[str | None] = mapped_column(String(64), index=True)
    num_frames: Mapped[int] = mapped_column(Integer)
    num_views: Mapped[int] = mapped_column(Integer)
    started_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
