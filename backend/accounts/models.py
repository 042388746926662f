"""Admin accounts (workers are identified by signed assignment tokens, not accounts here)."""

from __future__ import annotations

from sqlalchemy import Boolean, Integer, String
from sqlalchemy.orm import Mapped, mapped_column

from backend.db import Base, TimestampMixin


class Admin(TimestampMixin, Base):
    __tablename__ = "admins"

    id: Mapped[int] = mapped_column(primary_key=True)
    email: Mapped[str] = mapped_column(String(320), unique=True)
    password_hash: Mapped[str] = mapped_column(String(300))
    active: Mapped[bool] = mapped_column(Boolean, default=True)
    # Copied into every admin token; logout and a password change or reset move it on, which
    # ends every token issued before.
    token_epoch: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
