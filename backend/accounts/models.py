"""Accounts, one implementation with a role each: admins, and portal workers (each one a
marketplace worker id); and the invites an admin hands out to portal workers.

Both roles sign in with an email and a password and carry a token epoch: copied into every
token, moved on by logout and a password change or reset, which ends every token issued before.
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import Boolean, ForeignKey, Integer, String
from sqlalchemy.orm import Mapped, mapped_column

from backend.db import Base, TimestampMixin, UTCDateTime


class AccountColumns:
    """What every account has, whatever its role."""

    id: Mapped[int] = mapped_column(primary_key=True)
    email: Mapped[str] = mapped_column(String(320), unique=True)
    password_hash: Mapped[str] = mapped_column(String(300))
    active: Mapped[bool] = mapped_column(Boolean, default=True)
    token_epoch: Mapped[int] = mapped_column(Integer, default=0, server_default="0")


class Admin(AccountColumns, TimestampMixin, Base):
    __tablename__ = "admins"


class PortalAccount(AccountColumns, Base):
    """A worker who signs in to the portal; works on HITs as ``worker_id`` (market_workers)."""

    __tablename__ = "portal_accounts"

    worker_id: Mapped[str] = mapped_column(
        String(64), ForeignKey("market_workers.worker_id"), unique=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime)


class PortalInvite(Base):
    """A one-time registration link an admin hands out. Only the token's SHA-256 is stored,
    so a leaked database does not leak usable invites."""

    __tablename__ = "portal_invites"

    id: Mapped[int] = mapped_column(primary_key=True)
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    created_by: Mapped[int] = mapped_column(ForeignKey("admins.id"), index=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime)
    expires_at: Mapped[datetime] = mapped_column(UTCDateTime)
    used_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    account_id: Mapped[int | None] = mapped_column(
        Integer, ForeignKey("portal_accounts.id"), index=True)
