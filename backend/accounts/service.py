"""Admin accounts: creation, password login, password changes and signing out."""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.accounts.login import LoginRecord
from backend.accounts.models import Admin
from backend.db import session_scope
from backend.errors import Conflict, DexlabelError, Unauthorized
from backend.security import hash_password

MIN_PASSWORD_LENGTH = 10


def _check_password_rules(password: str) -> None:
    if len(password) < MIN_PASSWORD_LENGTH:
        raise DexlabelError(f"password must be at least {MIN_PASSWORD_LENGTH} characters")


def create_admin(session: Session, email: str, password: str, *, reset: bool = False) -> Admin:
    """A new admin, or with ``reset`` a new password for an existing one (which ends every
    token the admin was given before)."""
    email = email.strip().lower()
    if "@" not in email:
        raise DexlabelError(f"email {email!r} is not an email address")
    _check_password_rules(password)
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


def login_record(email: str) -> LoginRecord | None:
    """What a login needs of the admin with ``email`` (None: no such admin)."""
    with session_scope() as session:
        admin = session.scalars(
            select(Admin).where(Admin.email == email.strip().lower())).one_or_none()
        if admin is None:
            return None
        return LoginRecord(admin.id, admin.password_hash, admin.active, admin.token_epoch)


def change_password(session: Session, admin: Admin, password: str) -> Admin:
    """A new password; every token issued before ends."""
    _check_password_rules(password)
    admin.password_hash = hash_password(password)
    admin.token_epoch += 1
    session.flush()
    return admin


def sign_out(session: Session, admin: Admin) -> None:
    """Ends every token the admin holds (on every device)."""
    admin.token_epoch += 1
    session.flush()


def get_active_admin(session: Session, admin_id: int, token_epoch: object) -> Admin:
    """The admin of a token: it exists, is active and the token is of its current epoch."""
    admin = session.get(Admin, admin_id)
    if admin is None or not admin.active:
        raise Unauthorized("admin account no longer exists or is disabled")
    if token_epoch != admin.token_epoch:
        raise Unauthorized("this sign-in has ended (signed out, or the password was changed); "
                           "sign in again")
    return admin
