"""Admin accounts: creation and password login."""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.accounts.models import Admin
from backend.errors import Conflict, DexlabelError, Unauthorized
from backend.security import hash_password, verify_password

MIN_PASSWORD_LENGTH = 10


def create_admin(session: Session, email: str, password: str, *, reset: bool = False) -> Admin:
    """A new admin, or with ``reset`` a new password for an existing one."""
    email = email.strip().lower()
    if "@" not in email:
        raise DexlabelError(f"email {email!r} is not an email address")
    if len(password) < MIN_PASSWORD_LENGTH:
        raise DexlabelError(f"password must be at least {MIN_PASSWORD_LENGTH} characters")
    admin = session.scalars(select(Admin).where(Admin.email == email)).one_or_none()
    if admin is not None and not reset:
        raise Conflict(f"admin {email} already exists (use --reset to set a new password)")
    if admin is None:
        admin = Admin(email=email, password_hash="")
        session.add(admin)
    admin.password_hash = hash_password(password)
    admin.active = True
    session.flush()
    return admin


def authenticate(session: Session, email: str, password: str) -> Admin:
    admin = session.scalars(select(Admin).where(Admin.email == email.strip().lower())).one_or_none()
    if admin is None or not admin.active or not verify_password(password, admin.password_hash):
        raise Unauthorized("email or password is wrong")
    return admin


def get_active_admin(session: Session, admin_id: int) -> Admin:
    admin = session.get(Admin, admin_id)
    if admin is None or not admin.active:
        raise Unauthorized("admin account no longer exists or is disabled")
    return admin
