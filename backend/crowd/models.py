"""The requester's own records: published HITs, verified submissions, and the payment ledger.

Each row names the crowd ``provider`` that holds it (backend.crowd.providers); its ids
(``hit_id``: the provider's unit, ``worker_id``: its worker, ``target``: its allow-list) are
that provider's opaque strings, kept under the column names of the MTurk-only days. Amounts
are integer cents in the provider's currency. The ledger is what makes re-runs safe:
marketplace tokens expire after 24 hours, these rows do not.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    CheckConstraint,
    Float,
    Index,
    Integer,
    String,
    Text,
    UniqueConstraint,
    text,
)
from sqlalchemy.orm import Mapped, mapped_column

from backend.db import Base, TimestampMixin, UTCDateTime, one_of, parent_key

OPEN_SLOTS = "hit_id IS NOT NULL AND expired_at IS NULL AND max_assignments > decided"


class CrowdHit(TimestampMixin, Base):
    """One task published in one round; ``hit_id`` is null until the marketplace answered."""

    __tablename__ = "crowd_hits"
    __table_args__ = (
        UniqueConstraint("task_id", "round"),
        CheckConstraint("round >= 1", name="round_positive"),
        CheckConstraint("max_assignments >= 1", name="max_assignments_positive"),
        # The HITs with open slots (live, fewer decisions than assignments): the few the cost
        # report's committed money reads, among tens of thousands published.
        Index("ix_crowd_hits_open_task_id", "task_id",
              postgresql_where=text(OPEN_SLOTS), sqlite_where=text(OPEN_SLOTS)),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    task_id: Mapped[int] = parent_key("tasks.id")
    round: Mapped[int] = mapped_column(Integer, default=1)
    request_token: Mapped[str] = mapped_column(String(64), unique=True)
    hit_id: Mapped[str | None] = mapped_column(String(64), unique=True)
    max_assignments: Mapped[int] = mapped_column(Integer)
    reward_cents: Mapped[int] = mapped_column(Integer)
    expired_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    # Approvals and rejections of its assignments in our ledger, counted as each is written
    # (backend.crowd.totals): a live HIT's open slots are max_assignments - decided.
    decided: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    provider: Mapped[str] = mapped_column(String(16), default="mturk", server_default="mturk")
    # Why the unit was published under the adaptive policy (backend.crowd.adaptive), e.g.
    # "initial: widest baselines" or "frames 12-30 below confidence 0.5 after views 0, 3, 5";
    # null for a unit published with every view at once.
    reason: Mapped[str | None] = mapped_column(String(300))


class PublishPlan(TimestampMixin, Base):
    """How a sequence's views are published (backend.crowd.adaptive): the policy and its
    numbers as the last publish gave them, and that publish's options, which the publishes
    after each solve use again."""

    __tablename__ = "crowd_publish_plans"
    __table_args__ = (
        one_of("policy", ("every-view", "adaptive")),
        CheckConstraint("initial_views >= 2", name="initial_views_at_least_two"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    sequence_id: Mapped[int] = parent_key("sequences.id", unique=True)
    policy: Mapped[str] = mapped_column(String(16))
    initial_views: Mapped[int] = mapped_column(Integer)
    confidence: Mapped[float] = mapped_column(Float)
    confident_share: Mapped[float] = mapped_column(Float)
    # backend.crowd.schemas.PublishOptions as JSON (the reward, places, provider, ...).
    options: Mapped[dict[str, Any]] = mapped_column(JSON)


class CrowdSubmission(TimestampMixin, Base):
    """A submission whose assignment, HIT and worker ids matched the requester API's record."""

    __tablename__ = "crowd_submissions"

    id: Mapped[int] = mapped_column(primary_key=True)
    assignment_id: Mapped[int] = parent_key("assignments.id", unique=True)
    hit_id: Mapped[str] = mapped_column(String(64))
    worker_id: Mapped[str] = mapped_column(String(64))
    # The provider's status word as the ledger spells it ("Submitted", "Approved", "Rejected").
    market_status: Mapped[str] = mapped_column(String(16))
    provider: Mapped[str] = mapped_column(String(16), default="mturk", server_default="mturk")


class CrowdPayment(TimestampMixin, Base):
    """One approval, rejection or bonus; approvals and rejections are one per assignment."""

    __tablename__ = "crowd_payments"
    __table_args__ = (
        one_of("kind", ("approval", "rejection", "bonus")),
        CheckConstraint("amount_cents >= 0 AND fee_cents >= 0", name="amounts_nonnegative"),
        one_of("state", ("pending", "done")),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))
    assignment_id: Mapped[int] = parent_key("assignments.id", index=True)
    worker_id: Mapped[str] = mapped_column(String(64), index=True)
    # Deterministic: "approval-<assignment>", "rejection-<assignment>" or a bonus token.
    request_token: Mapped[str] = mapped_column(String(64), unique=True)
    amount_cents: Mapped[int] = mapped_column(Integer, default=0)
    fee_cents: Mapped[int] = mapped_column(Integer, default=0)
    feedback: Mapped[str | None] = mapped_column(Text)
    # "pending": written and committed before the marketplace call, so a run whose reply or
    # commit was lost finds it and checks the marketplace instead of paying again; "done" after.
    state: Mapped[str] = mapped_column(String(16), default="done", server_default="done")
    provider: Mapped[str] = mapped_column(String(16), default="mturk", server_default="mturk")


class CrowdQualification(TimestampMixin, Base):
    """A qualification type we created on the marketplace, found again by name."""

    __tablename__ = "crowd_qualifications"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(128), unique=True)
    qualification_type_id: Mapped[str] = mapped_column(String(64), unique=True)


class CrowdWorkerAction(TimestampMixin, Base):
    """The current state of a per-worker action: a block, or a qualification grant."""

    __tablename__ = "crowd_worker_actions"
    __table_args__ = (
        UniqueConstraint("worker_id", "kind", "target"),
        one_of("kind", ("block", "qualification")),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    worker_id: Mapped[str] = mapped_column(String(64))
    kind: Mapped[str] = mapped_column(String(16))
    # The qualification type id of a grant; "" for a block.
    target: Mapped[str] = mapped_column(String(64), default="")
    value: Mapped[int | None] = mapped_column(Integer)
    reason: Mapped[str | None] = mapped_column(Text)
    provider: Mapped[str] = mapped_column(String(16), default="mturk", server_default="mturk")


class CrowdDeletedCost(TimestampMixin, Base):
    """What the ledger held for a sequence deleted with its work, per worker and kind: the
    payment rows go with the sequence, the money spent stays in the cost report."""

    __tablename__ = "crowd_deleted_costs"

    id: Mapped[int] = mapped_column(primary_key=True)
    sequence_id: Mapped[int] = mapped_column(Integer)  # the deleted sequence's id (no key)
    sequence_name: Mapped[str] = mapped_column(String(300))  # "subject/name"
    worker_id: Mapped[str] = mapped_column(String(64))
    kind: Mapped[str] = mapped_column(String(16))
    state: Mapped[str] = mapped_column(String(16))
    amount_cents: Mapped[int] = mapped_column(BigInteger)
    fee_cents: Mapped[int] = mapped_column(BigInteger)
    payments: Mapped[int] = mapped_column(Integer)
    provider: Mapped[str] = mapped_column(String(16), default="mturk", server_default="mturk")


class CrowdCostTotal(Base):
    """Running sums of the payment ledger, per sequence and per worker, by kind and state:
    written in the transaction that writes or changes each payment row (backend.crowd.totals),
    so they always equal the sums over crowd_payments, and the cost report reads a few
    thousand rows instead of joining the whole ledger to its assignments, tasks and HITs."""

    __tablename__ = "crowd_cost_totals"
    __table_args__ = (
        UniqueConstraint("scope", "key", "kind", "state"),
        one_of("scope", ("sequence", "worker", "provider")),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    scope: Mapped[str] = mapped_column(String(16))
    key: Mapped[str] = mapped_column(String(64))  # the sequence id, worker id or provider
    kind: Mapped[str] = mapped_column(String(16))
    state: Mapped[str] = mapped_column(String(16))
    amount_cents: Mapped[int] = mapped_column(BigInteger, default=0)
    fee_cents: Mapped[int] = mapped_column(BigInteger, default=0)
    payments: Mapped[int] = mapped_column(Integer, default=0)
