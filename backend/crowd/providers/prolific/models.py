"""Our own records of what we asked of Prolific: studies, their units, bonuses, webhooks.

Each row is written (and committed) before the call it guards, so a run whose reply was lost
finds it and looks at Prolific before it creates, publishes or pays again. Amounts are integer
minor units (pence, cents) in ``DEXLABEL_PROLIFIC_CURRENCY``.
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import JSON, Integer, String, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column

from backend.db import Base, TimestampMixin, UTCDateTime, one_of, parent_key

STUDY_STATES = ("creating", "created", "coded", "published")
BONUS_STATES = ("created", "paying", "paid")


class ProlificStudy(TimestampMixin, Base):
    """One Taskflow study: one publish of a batch of units.

    ``state`` says how far the publish got: "creating" (row written, the study maybe made on
    Prolific: look it up by ``internal_name`` before making another), "created" (``study_id``
    known), "coded" (our completion code patched on), "published".
    """

    __tablename__ = "prolific_studies"
    __table_args__ = (one_of("state", STUDY_STATES),)

    id: Mapped[int] = mapped_column(primary_key=True)
    # Deterministic from the batch's unit keys: the same units asked again find this row.
    batch_key: Mapped[str] = mapped_column(String(64), unique=True)
    internal_name: Mapped[str] = mapped_column(String(128), unique=True)
    study_id: Mapped[str | None] = mapped_column(String(64), unique=True)
    state: Mapped[str] = mapped_column(String(16), default="creating")
    completion_code: Mapped[str] = mapped_column(String(32))
    reward_cents: Mapped[int] = mapped_column(Integer)
    allotted_s: Mapped[int] = mapped_column(Integer)
    # Prolific's study status as last seen (a study.status.change webhook, or a read).
    status: Mapped[str | None] = mapped_column(String(32))


class ProlificUnit(TimestampMixin, Base):
    """One unit of work: one access detail (external URL) of a study; its unit id is
    "<study_id>:<position>"."""

    __tablename__ = "prolific_units"
    __table_args__ = (UniqueConstraint("study_row_id", "position"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    study_row_id: Mapped[int] = parent_key("prolific_studies.id", index=True)
    key: Mapped[str] = mapped_column(String(64), unique=True)
    position: Mapped[int] = mapped_column(Integer)
    task_id: Mapped[int] = mapped_column(Integer)
    places: Mapped[int] = mapped_column(Integer)
    external_url: Mapped[str] = mapped_column(String(2000))
    # The add-places requests already counted into ``places`` (their keys): asked again, the
    # study's total is sent again as it stands, never raised twice.
    place_keys: Mapped[list[str]] = mapped_column(JSON, default=list)
    # Closed by us: Prolific cannot close one access detail of a running study, so the unit
    # reports itself closed and the study is stopped once every unit of it is closed.
    closed_at: Mapped[datetime | None] = mapped_column(UTCDateTime)


class ProlificBonus(TimestampMixin, Base):
    """One bonus: "created" (row written; ``bulk_id`` once Prolific set it up), "paying"
    (the pay call was sent: whether it was carried out is asked of Prolific before paying
    again), "paid"."""

    __tablename__ = "prolific_bonuses"
    __table_args__ = (one_of("state", BONUS_STATES),)

    id: Mapped[int] = mapped_column(primary_key=True)
    key: Mapped[str] = mapped_column(String(64), unique=True)
    study_id: Mapped[str] = mapped_column(String(64))
    submission_id: Mapped[str] = mapped_column(String(64))
    participant_id: Mapped[str] = mapped_column(String(64))
    amount_cents: Mapped[int] = mapped_column(Integer)
    bulk_id: Mapped[str | None] = mapped_column(String(64))
    state: Mapped[str] = mapped_column(String(16), default="created")


class ProlificWebhookEvent(TimestampMixin, Base):
    """A webhook already acted on, by the SHA-256 of its signature: the same request sent
    again (a replay) is refused."""

    __tablename__ = "prolific_webhook_events"

    id: Mapped[int] = mapped_column(primary_key=True)
    digest: Mapped[str] = mapped_column(String(64), unique=True)
    event_type: Mapped[str] = mapped_column(String(64))
    resource_id: Mapped[str] = mapped_column(String(64))


class ProlificLease(Base):
    """A named lease one process holds at a time (the workspace wallet: bonuses are paid one
    at a time across every process): taken by one conditional UPDATE, which SQLite and
    PostgreSQL both carry out atomically, and given back after; a holder that died loses it
    when ``until`` passes."""

    __tablename__ = "prolific_leases"

    name: Mapped[str] = mapped_column(String(32), primary_key=True)
    holder: Mapped[str | None] = mapped_column(String(64))
    until: Mapped[datetime | None] = mapped_column(UTCDateTime)
