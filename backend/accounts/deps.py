"""Request authorisation: admins by bearer token; frame viewers by bearer or a view token."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from backend.accounts.models import Admin
from backend.accounts.service import get_active_admin
from backend.config import get_settings
from backend.db import SessionDep
from backend.errors import Forbidden, Unauthorized
from backend.security import verify_token

ADMIN_SCOPE = "admin"
VIEW_SCOPE = "view"
# Tokens of these scopes carry a sequence_id and serial and may read that view's frames.
FRAME_SCOPES = ("view", "task", "assignment")


def bearer_token(request: Request) -> str | None:
    header = request.headers.get("authorization", "")
    scheme, _, token = header.partition(" ")
    return token.strip() if scheme.lower() == "bearer" and token.strip() else None


def current_admin(request: Request, session: SessionDep) -> Admin:
    token = bearer_token(request)
    if token is None:
        raise Unauthorized("admin login required: send 'Authorization: Bearer <token>'")
    payload = verify_token(token, get_settings().secret_key, ADMIN_SCOPE)
    return get_active_admin(session, int(payload["sub"]))


CurrentAdmin = Annotated[Admin, Depends(current_admin)]


def require_view_access(
    request: Request, session: SessionDep, sequence_id: int, serial: str
) -> None:
    """An admin, or the holder of a view token for exactly this sequence and camera."""
    if bearer_token(request) is not None:
        current_admin(request, session)
        return
    token = request.query_params.get("token")
    if not token:
        raise Unauthorized("send an admin bearer token or a view token (?token=...)")
    payload = _frame_token(token)
    if payload.get("sequence_id") != sequence_id or payload.get("serial") != serial:
        raise Forbidden("this view token is for another sequence or camera")


def _frame_token(token: str) -> dict:
    """The payload of a token that may read one view's frames: view, task or assignment."""
    return verify_token(token, get_settings().secret_key, FRAME_SCOPES)
