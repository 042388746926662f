"""Portal accounts: created by an admin or through an invite link (signing in, password
changes and signing out are backend.accounts.service's, as for admins).

Each account is one marketplace worker: its ``worker_id`` (an MTurk-style CustomerId) is what
requesters see on assignments, bonuses and qualifications.
"""

from __future__ import annotations

import hashlib
import secrets
from datetime import datetime, timedelta

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.accounts.models import Admin, PortalAccount, PortalInvite
from backend.accounts.service import check_password_rules, normalise_email
from backend.errors import Conflict, NotFound
from backend.market.workers import get_or_create_worker
from backend.security import hash_password

WORKER_ID_DIGITS = 13  # MTurk worker ids are 'A' and 12 to 14 more capitals or digits


def _new_worker_id(session: Session) -> str:
    while True:
        worker_id = "A" + secrets.token_hex(8).upper()[:WORKER_ID_DIGITS]
        taken = session.scalar(select(PortalAccount.id).where(PortalAccount.worker_id == worker_id))
        if taken is None:
            return worker_id


def create_account(session: Session, email: str, password: str, now: datetime) -> PortalAccount:
    """A new worker account with a fresh marketplace worker id."""
    email = normalise_email(email)
    check_password_rules(password)
    if session.scalar(select(PortalAccount.id).where(PortalAccount.email == email)) is not None:
        raise Conflict(f"a worker account for {email} already exists")
    worker = get_or_create_worker(session, _new_worker_id(session), now)
    account = PortalAccount(email=email, password_hash=hash_password(password),
                            worker_id=worker.worker_id, active=True, created_at=now,
                            token_epoch=0)
    session.add(account)
    session.flush()
    return account


def _token_hash(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def create_invite(
    session: Session, admin: Admin, ttl: timedelta, now: datetime
) -> tuple[str, PortalInvite]:
    """A one-time invite: the token to hand out (shown once) and its record."""
    token = secrets.token_urlsafe(24)
    invite = PortalInvite(token_hash=_token_hash(token), created_by=admin.id, created_at=now,
                          expires_at=now + ttl)
    session.add(invite)
    session.flush()
    return token, invite


def register(
    session: Session, token: str, email: str, password: str, now: datetime
) -> PortalAccount:
    """Redeem an invite for a new account; each invite works once, before it expires."""
    invite = session.scalars(
        select(PortalInvite).where(PortalInvite.token_hash == _token_hash(token))
        .with_for_update()).one_or_none()
    if invite is None:
        raise NotFound("this invite link is not valid")
    if invite.used_at is not None:
        raise Conflict("this invite link was already used")
    if invite.expires_at <= now:
        raise Conflict("this invite link has expired")
    account = create_account(session, email, password, now)
    invite.used_at, invite.account_id = now, account.id
    session.flush()
    return account
