"""Marketplace records: HIT types, HITs, assignments, bonuses, qualifications, blocks, ledger.

Every table has an integer primary key (stable keyset pagination) and, where MTurk names the
thing, a public id (HITId, AssignmentId, ...) that is unique. ``requester`` is the access key id
of the requester account that owns the record. Money is integer cents. HIT and assignment
states that depend on time are derived against the marketplace clock (see ``hits.py``).
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    CheckConstraint,
    ForeignKey,
    Index,
    Integer,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import Mapped, mapped_column, relationship

from backend.db import Base, UTCDateTime, one_of

ASSIGNMENT_STATUSES = ("Accepted", "Submitted", "Approved", "Rejected", "Returned", "Abandoned")
LEDGER_KINDS = ("hold", "release", "pay", "bonus")


class HitType(Base):
    """Shared properties of HITs; identical properties of one requester share one type."""

    __tablename__ = "market_hit_types"
    __table_args__ = (
        UniqueConstraint("requester", "fingerprint"),
        CheckConstraint("reward_cents >= 0", name="reward_nonnegative"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    type_id: Mapped[str] = mapped_column(String(64), unique=True)
    group_id: Mapped[str] = mapped_column(String(64))
    requester: Mapped[str] = mapped_column(String(128), index=True)
    # SHA-256 of the canonical JSON of the properties below.
    fingerprint: Mapped[str] = mapped_column(String(64))
    title: Mapped[str] = mapped_column(String(128))
    description: Mapped[str] = mapped_column(Text)
    keywords: Mapped[str | None] = mapped_column(Text)
    reward_cents: Mapped[int] = mapped_column(BigInteger)
    assignment_duration_s: Mapped[int] = mapped_column(BigInteger)
    auto_approval_delay_s: Mapped[int] = mapped_column(BigInteger)
    qualification_requirements: Mapped[list[dict[str, Any]]] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime)


class Hit(Base):
    __tablename__ = "market_hits"
    __table_args__ = (
        CheckConstraint("max_assignments >= 1", name="max_assignments_positive"),
        CheckConstraint("held_slots >= 0", name="held_slots_nonnegative"),
        Index("ix_market_hits_settled_expiration", "settled", "expiration"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    hit_id: Mapped[str] = mapped_column(String(64), unique=True)
    requester: Mapped[str] = mapped_column(String(128), index=True)
    hit_type_pk: Mapped[int] = mapped_column(ForeignKey("market_hit_types.id"), index=True)
    question: Mapped[str] = mapped_column(Text)
    requester_annotation: Mapped[str | None] = mapped_column(Text)
    max_assignments: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime)
    expiration: Mapped[datetime] = mapped_column(UTCDateTime)
    disposed_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    # Set by UpdateHITReviewStatus: a Reviewable HIT the requester is working through.
    reviewing: Mapped[bool] = mapped_column(Boolean, default=False)
    # Assignment slots whose reward and fee are held from the requester's balance.
    held_slots: Mapped[int] = mapped_column(Integer, default=0)
    # True once nothing time-driven can change this HIT's held funds any more.
    settled: Mapped[bool] = mapped_column(Boolean, default=False)
    # Optimistic lock: two units of work that both move this HIT's held funds cannot both win.
    version: Mapped[int] = mapped_column(Integer)

    __mapper_args__: Mapping[str, Any] = {"version_id_col": version}

    hit_type: Mapped[HitType] = relationship()
    assignments: Mapped[list[MarketAssignment]] = relationship(
        back_populates="hit", order_by="MarketAssignment.id")


class MarketAssignment(Base):
    """One worker's go at a HIT (MTurk's Assignment; named apart from the annotation domain's
    Assignment, which shares the declarative registry). Accepted, Returned and Abandoned are
    marketplace-internal; the requester API shows only Submitted, Approved and Rejected ones."""

    __tablename__ = "market_assignments"
    __table_args__ = (
        one_of("status", ASSIGNMENT_STATUSES),
        Index("ix_market_assignments_status_auto_approval_time", "status", "auto_approval_time"),
        Index("ix_market_assignments_status_deadline", "status", "deadline"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    assignment_id: Mapped[str] = mapped_column(String(64), unique=True)
    hit_pk: Mapped[int] = mapped_column(ForeignKey("market_hits.id"), index=True)
    worker_id: Mapped[str] = mapped_column(String(64), index=True)
    status: Mapped[str] = mapped_column(String(16))
    accept_time: Mapped[datetime] = mapped_column(UTCDateTime)
    deadline: Mapped[datetime] = mapped_column(UTCDateTime)
    submit_time: Mapped[datetime | None] = mapped_column(UTCDateTime)
    auto_approval_time: Mapped[datetime | None] = mapped_column(UTCDateTime)
    approval_time: Mapped[datetime | None] = mapped_column(UTCDateTime)
    rejection_time: Mapped[datetime | None] = mapped_column(UTCDateTime)
    # QuestionFormAnswers XML (2005-10-01) as the worker submitted it.
    answer: Mapped[str | None] = mapped_column(Text)
    requester_feedback: Mapped[str | None] = mapped_column(Text)

    hit: Mapped[Hit] = relationship(back_populates="assignments")


class Bonus(Base):
    __tablename__ = "market_bonuses"
    __table_args__ = (CheckConstraint("amount_cents > 0", name="amount_positive"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    requester: Mapped[str] = mapped_column(String(128), index=True)
    worker_id: Mapped[str] = mapped_column(String(64), index=True)
    assignment_pk: Mapped[int] = mapped_column(ForeignKey("market_assignments.id"), index=True)
    amount_cents: Mapped[int] = mapped_column(BigInteger)
    reason: Mapped[str] = mapped_column(Text)
    grant_time: Mapped[datetime] = mapped_column(UTCDateTime)

    assignment: Mapped[MarketAssignment] = relationship()


class QualificationType(Base):
    __tablename__ = "market_qualification_types"
    __table_args__ = (
        UniqueConstraint("requester", "name"),
        one_of("status", ("Active", "Inactive")),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    type_id: Mapped[str] = mapped_column(String(64), unique=True)
    requester: Mapped[str] = mapped_column(String(128), index=True)
    name: Mapped[str] = mapped_column(String(255))
    description: Mapped[str] = mapped_column(Text)
    keywords: Mapped[str | None] = mapped_column(Text)
    status: Mapped[str] = mapped_column(String(8))
    retry_delay_s: Mapped[int | None] = mapped_column(BigInteger)
    test: Mapped[str | None] = mapped_column(Text)
    answer_key: Mapped[str | None] = mapped_column(Text)
    test_duration_s: Mapped[int | None] = mapped_column(BigInteger)
    auto_granted: Mapped[bool] = mapped_column(Boolean, default=False)
    auto_granted_value: Mapped[int | None] = mapped_column(Integer)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime)


class Qualification(Base):
    """A worker's qualification of one type: its value, and whether it is granted or revoked."""

    __tablename__ = "market_qualifications"
    __table_args__ = (
        UniqueConstraint("type_pk", "worker_id"),
        one_of("status", ("Granted", "Revoked")),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    type_pk: Mapped[int] = mapped_column(ForeignKey("market_qualification_types.id"))
    worker_id: Mapped[str] = mapped_column(String(64), index=True)
    integer_value: Mapped[int | None] = mapped_column(Integer)
    status: Mapped[str] = mapped_column(String(8))
    grant_time: Mapped[datetime] = mapped_column(UTCDateTime)
    revoke_reason: Mapped[str | None] = mapped_column(Text)

    qualification_type: Mapped[QualificationType] = relationship()


class Worker(Base):
    """A worker known to the marketplace; the worker portal adds its account fields."""

    __tablename__ = "market_workers"

    id: Mapped[int] = mapped_column(primary_key=True)
    worker_id: Mapped[str] = mapped_column(String(64), unique=True)
    # ISO 3166 country and subdivision, matched by Worker_Locale requirements.
    locale_country: Mapped[str | None] = mapped_column(String(2))
    locale_subdivision: Mapped[str | None] = mapped_column(String(3))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime)


class WorkerBlock(Base):
    __tablename__ = "market_worker_blocks"
    __table_args__ = (UniqueConstraint("requester", "worker_id"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    requester: Mapped[str] = mapped_column(String(128))
    worker_id: Mapped[str] = mapped_column(String(64), index=True)
    reason: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime)


class Notification(Base):
    """A message from a requester to a worker (NotifyWorkers, qualification grants)."""

    __tablename__ = "market_notifications"

    id: Mapped[int] = mapped_column(primary_key=True)
    requester: Mapped[str] = mapped_column(String(128))
    worker_id: Mapped[str] = mapped_column(String(64), index=True)
    subject: Mapped[str] = mapped_column(String(200))
    message: Mapped[str] = mapped_column(Text)
    sent_at: Mapped[datetime] = mapped_column(UTCDateTime)


class RequestToken(Base):
    """A UniqueRequestToken seen from a requester, and what its first request produced."""

    __tablename__ = "market_request_tokens"
    __table_args__ = (UniqueConstraint("requester", "operation", "token"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    requester: Mapped[str] = mapped_column(String(128))
    operation: Mapped[str] = mapped_column(String(64))
    token: Mapped[str] = mapped_column(String(64))
    request_id: Mapped[str] = mapped_column(String(64))
    # The HITId (CreateHIT, CreateAdditionalAssignmentsForHIT) or bonus id it produced.
    entity_id: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime)


class LedgerEntry(Base):
    """One movement of a requester's money.

    ``available_cents`` changes the spendable balance (negative: money leaves it);
    ``held_cents`` changes the amount held for outstanding assignments. Creating a HIT moves
    reward plus fee from available to held; approval pays out of held; rejection and expiry
    move it back; bonuses and approvals that override a rejection pay from available.
    """

    __tablename__ = "market_ledger"
    __table_args__ = (one_of("kind", LEDGER_KINDS),)

    id: Mapped[int] = mapped_column(primary_key=True)
    requester: Mapped[str] = mapped_column(String(128), index=True)
    kind: Mapped[str] = mapped_column(String(16))
    available_cents: Mapped[int] = mapped_column(BigInteger)
    held_cents: Mapped[int] = mapped_column(BigInteger)
    hit_pk: Mapped[int | None] = mapped_column(ForeignKey("market_hits.id"), index=True)
    assignment_pk: Mapped[int | None] = mapped_column(ForeignKey("market_assignments.id"))
    bonus_pk: Mapped[int | None] = mapped_column(ForeignKey("market_bonuses.id"))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime)
