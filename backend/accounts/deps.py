"""Request authorisation: admins and portal workers by bearer token (backend.accounts.service);
frame viewers by an admin's bearer token or a view token."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Query, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from backend.accounts.models import Admin, PortalAccount
from backend.accounts.service import ADMIN, WORKER, signed_in_account
from backend.config import get_settings
from backend.db import SessionDep
from backend.errors import Forbidden, Unauthorized
from backend.security import sign_token, verify_token
from backend.validation import Id, Key

VIEW_SCOPE = "view"
# The only tokens a frame URL (?token=) may carry: read-only view tokens of one sequence and
# camera. The write-capable assignment token is sent as a header only, never in a URL, where
# access logs and browser histories would keep it.
FRAME_SCOPES = (VIEW_SCOPE,)


# The API document's bearer scheme, so /docs has an Authorize button whose token is sent with
# every operation that declares it. It only declares: each dependency below reads the header
# itself (bearer_token) and answers a missing or wrong token with our own 401.
BEARER = HTTPBearer(
    auto_error=False, scheme_name="bearer",
    description="An admin's token from POST /api/auth/token, a portal worker's from POST "
                "/api/portal/login, or an annotation page's token from its link.")
# The scheme as a dependency; a direct call (not through FastAPI) passes nothing.
BearerCredentials = Annotated[HTTPAuthorizationCredentials | None, Depends(BEARER)]


def bearer_token(request: Request) -> str | None:
    header = request.headers.get("authorization", "")
    scheme, _, token = header.partition(" ")
    return token.strip() if scheme.lower() == "bearer" and token.strip() else None


def view_token(sequence_id: int, serial: str, ttl_s: int) -> str:
    """A read-only token for one view's frames, the only token fit for a URL."""
    payload = {"scope": VIEW_SCOPE, "sequence_id": sequence_id, "serial": serial}
    return sign_token(payload, get_settings().signing_key, ttl_s)


def current_admin(request: Request, session: SessionDep,
                  _scheme: BearerCredentials = None) -> Admin:
    account: Admin = signed_in_account(ADMIN, session, bearer_token(request))
    return account


def current_worker(request: Request, session: SessionDep,
                   _scheme: BearerCredentials = None) -> PortalAccount:
    account: PortalAccount = signed_in_account(WORKER, session, bearer_token(request))
    return account


CurrentAdmin = Annotated[Admin, Depends(current_admin)]
CurrentWorker = Annotated[PortalAccount, Depends(current_worker)]


ViewTokenQuery = Annotated[str | None, Query(
    max_length=4096, description="a view token of this sequence and camera, instead of an "
                                 "admin's bearer token")]


def require_view_access(
    request: Request, session: SessionDep, sequence_id: Id, serial: Key,
    token: ViewTokenQuery = None, _scheme: BearerCredentials = None,
) -> None:
    """An admin, or the holder of a view token for exactly this sequence and camera."""
    if bearer_token(request) is not None:
        current_admin(request, session)
        return
    if not token:
        raise Unauthorized("send an admin bearer token or a view token (?token=...)")
    payload = _frame_token(token)
    if payload.get("sequence_id") != sequence_id or payload.get("serial") != serial:
        raise Forbidden("this view token is for another sequence or camera")


def _frame_token(token: str) -> dict:
    """The payload of a token that may read one view's frames: a view token only."""
    return verify_token(token, get_settings().signing_key, FRAME_SCOPES)
