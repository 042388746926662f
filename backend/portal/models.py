"""Worker portal records: worker accounts (each one a marketplace worker id) and invites."""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import Boolean, ForeignKey, Integer, String
from sqlalchemy.orm import Mapped, mapped_column

from backend.db import Base
from backend.market.models import UTCDateTime


class PortalAccount(Base):
    """A worker who signs in to the portal; works on HITs as ``worker_id`` (market_workers)."""

    __tablename__ = "portal_accounts"

    id: Mapped[int] = mapped_column(primary_key=True)
    email: Mapped[str] = mapped_column(String(320), unique=True)
    password_hash: Mapped[str] = mapped_column(String(300))
    worker_id: Mapped[str] = mapped_column(
        String(64), ForeignKey("market_workers.worker_id"), unique=True)
    active: Mapped[bool] = mapped_column(Boolean, default=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime)
    # Copied into every portal token; logout and a password change move it on, which ends
    # every token issued before.
    token_epoch: Mapped[int] = mapped_column(Integer, default=0, server_default="0")


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
