"""Accounts, one implementation for both roles (an admin, a portal worker): password rules,
creating an admin, what a login reads, password changes, signing out, and the token of a
signed-in account (issued, and checked on each request).

A role says which table its accounts live in, its tokens' scope and lifetime, its login realm
(the login limits count per realm) and any claim its tokens carry besides the account id and
epoch (a portal worker's marketplace worker id).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

from fastapi import Request
from sqlalchemy import select
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from backend.accounts.login import LoginRecord, password_check, password_login
from backend.accounts.models import AccountColumns, Admin, PortalAccount
from backend.config import get_settings
from backend.db import session_scope
from backend.errors import Conflict, DexlabelError, Unauthorized
from backend.security import hash_password, sign_token, verify_token

MIN_PASSWORD_LENGTH = 10
TOKEN_TTL_S = 12 * 3600

AccountT = TypeVar("AccountT", bound=AccountColumns)


def _no_claims(_: Any) -> dict[str, Any]:
    return {}


@dataclass(frozen=True)
class Role:
    """One kind of account (see the module)."""

    noun: str  # "admin", "worker": in the messages a refused token gets
    model: type[AccountColumns]
    scope: str
    realm: str
    ttl_s: int = TOKEN_TTL_S
    # Claims a token carries besides sub and epoch, each checked against the account.
    claims: Callable[[Any], dict[str, Any]] = field(default=_no_claims)


ADMIN = Role("admin", Admin, scope="admin", realm="admin")
WORKER = Role("worker", PortalAccount, scope="portal", realm="portal",
              claims=lambda account: {"worker_id": account.worker_id})


def normalise_email(email: str) -> str:
    """``email`` trimmed and lower-cased; DexlabelError when it is not an email address."""
    email = email.strip().lower()
    if "@" not in email or email.startswith("@") or email.endswith("@"):
        raise DexlabelError(f"email {email!r} is not an email address")
    return email


def check_password_rules(password: str) -> None:
    if len(password) < MIN_PASSWORD_LENGTH:
        raise DexlabelError(f"password must be at least {MIN_PASSWORD_LENGTH} characters")


def create_admin(session: Session, email: str, password: str, *, reset: bool = False) -> Admin:
    """A new admin, or with ``reset`` a new password for an existing one (which ends every
    token the admin was given before)."""
    email = normalise_email(email)
    check_password_rules(password)
    admin = session.scalars(select(Admin).where(Admin.email == email)).one_or_none()
    if admin is not None and not reset:
        raise Conflict(f"admin {email} already exists (use --reset to set a new password)")
    if admin is None:
        admin = Admin(email=email, password_hash="", token_epoch=0)
        session.add(admin)
    else:
        admin.token_epoch += 1
    admin.password_hash = hash_password(password)
    admin.active = True
    session.flush()
    return admin


def login_record(role: Role, email: str) -> LoginRecord | None:
    """What a login needs of the account of ``role`` with ``email`` (None: no such account)."""
    with session_scope() as session:
        account = session.scalars(select(role.model).where(
            role.model.email == email.strip().lower())).one_or_none()
        if account is None:
            return None
        return LoginRecord(account.id, account.password_hash, account.active,
                           account.token_epoch, role.claims(account).get("worker_id"))


def change_password(session: Session, account: AccountT, password: str) -> AccountT:
    """A new password; every token issued before ends."""
    check_password_rules(password)
    account.password_hash = hash_password(password)
    account.token_epoch += 1
    session.flush()
    return account


def sign_out(session: Session, account: AccountColumns) -> None:
    """Ends every token the account holds (on every device)."""
    account.token_epoch += 1
    session.flush()


def account_token(role: Role, account_id: int, token_epoch: int, **claims: Any) -> str:
    """A bearer token of ``role``, valid until the role's TTL or until the account's token
    epoch moves on (logout, password change or reset)."""
    payload = {"scope": role.scope, "sub": account_id, **claims, "epoch": token_epoch}
    return sign_token(payload, get_settings().signing_key, role.ttl_s)


def signed_in_account(role: Role, session: Session, token: str | None) -> Any:
    """The account of ``role`` a bearer token belongs to: signed for the role, the account
    exists, is active, and the token carries its claims and current epoch."""
    if token is None:
        raise Unauthorized(f"{role.noun} login required: send 'Authorization: Bearer <token>'")
    payload = verify_token(token, get_settings().signing_key, role.scope)
    account = session.get(role.model, int(payload["sub"]))
    if account is None or not account.active:
        raise Unauthorized(f"{role.noun} account no longer exists or is disabled")
    if any(payload.get(name) != value for name, value in role.claims(account).items()):
        raise Unauthorized(f"token does not belong to this {role.noun} account")
    if payload.get("epoch") != account.token_epoch:
        raise Unauthorized("this sign-in has ended (signed out, or the password was changed); "
                           "sign in again")
    return account


async def sign_in(request: Request, role: Role, email: str, password: str) -> LoginRecord:
    """A password login of ``role`` under the login limits (backend.accounts.login)."""
    return await password_login(request, role.realm, email, password,
                                lambda address: login_record(role, address))


async def new_password(request: Request, role: Role, session: Session, account: AccountT,
                       current: str, password: str) -> AccountT:
    """A signed-in account's password change: its current password checked under the login
    limits, then the new one set (every token issued before ends)."""
    await password_check(request, role.realm, account.email, current, account.password_hash)
    return await run_in_threadpool(change_password, session, account, password)
