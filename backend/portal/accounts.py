"""Portal accounts: created by an admin or through an invite link; password login.

Each account is one marketplace worker: its ``worker_id`` (an MTurk-style CustomerId) is what
requesters see on assignments, bonuses and qualifications.
"""

from __future__ import annotations

import hashlib
import secrets
from datetime import datetime, timedelta

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.accounts.login import LoginRecord
from backend.accounts.models import Admin
from backend.db import session_scope
from backend.errors import Conflict, DexlabelError, NotFound, Unauthorized
from backend.market.workers import get_or_create_worker
from backend.portal.models import PortalAccount, PortalInvite
from backend.security import hash_password, verify_password

MIN_PASSWORD_LENGTH = 10
WORKER_ID_DIGITS = 13  # MTurk worker ids are 'A' and 12 to 14 more capitals or digits


def _normalise_email(email: str) -> str:
    email = email.strip().lower()
    if "@" not in email or email.startswith("@") or email.endswith("@"):
        raise DexlabelError(f"email {email!r} is not an email address")
    return email


def _new_worker_id(session: Session) -> str:
    while True:
        worker_id = "A" + secrets.token_hex(8).upper()[:WORKER_ID_DIGITS]
        taken = session.scalar(select(PortalAccount.id).where(PortalAccount.worker_id == worker_id))
        if taken is None:
            return worker_id


def create_account(session: Session, email: str, password: str, now: datetime) -> PortalAccount:
    """A new worker account with a fresh marketplace worker id."""
    email = _normalise_email(email)
    if len(password) < MIN_PASSWORD_LENGTH:
        raise DexlabelError(f"password must be at least {MIN_PASSWORD_LENGTH} characters")
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


def authenticate(session: Session, email: str, password: str) -> PortalAccount:
    """The active account of ``email`` if ``password`` is its password (an unknown email takes
    as long to refuse as a wrong password)."""
    account = session.scalars(select(PortalAccount).where(
        PortalAccount.email == email.strip().lower())).one_or_none()
    ok = verify_password(password, account.password_hash if account is not None else None)
    if account is None or not account.active or not ok:
        raise Unauthorized("email or password is wrong")
    return account


def login_record(email: str) -> LoginRecord | None:
    """What a login needs of the account of ``email`` (None: no such account)."""
    with session_scope() as session:
        account = session.scalars(select(PortalAccount).where(
            PortalAccount.email == email.strip().lower())).one_or_none()
        if account is None:
            return None
        return LoginRecord(account.id, account.password_hash, account.active,
                           account.token_epoch, account.worker_id)


def change_password(session: Session, account: PortalAccount, password: str) -> PortalAccount:
    """A new password; every token issued before ends."""
    if len(password) < MIN_PASSWORD_LENGTH:
        raise DexlabelError(f"password must be at least {MIN_PASSWORD_LENGTH} characters")
    account.password_hash = hash_password(password)
    account.token_epoch += 1
    session.flush()
    return account


def sign_out(session: Session, account: PortalAccount) -> None:
    """Ends every token the worker holds (on every device)."""
    account.token_epoch += 1
    session.flush()


def get_active_account(session: Session, account_id: int) -> PortalAccount:
    account = session.get(PortalAccount, account_id)
    if account is None or not account.active:
        raise Unauthorized("worker account no longer exists or is disabled")
    return account
