"""Portal authorisation: a worker's signed token of scope "portal", sent as a bearer header
(never a cookie, like every token of the product)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from backend.accounts.deps import bearer_token
from backend.config import get_settings
from backend.db import SessionDep
from backend.errors import Unauthorized
from backend.portal.accounts import get_active_account
from backend.portal.models import PortalAccount
from backend.security import sign_token, verify_token

PORTAL_SCOPE = "portal"
PORTAL_TOKEN_TTL_S = 12 * 3600


def portal_token(account_id: int, worker_id: str, token_epoch: int) -> str:
    """A worker's bearer token, valid until its TTL or until the account's token epoch moves
    on (logout or password change)."""
    payload = {"scope": PORTAL_SCOPE, "sub": account_id, "worker_id": worker_id,
               "epoch": token_epoch}
    return sign_token(payload, get_settings().signing_key, PORTAL_TOKEN_TTL_S)


def current_worker(request: Request, session: SessionDep) -> PortalAccount:
    token = bearer_token(request)
    if token is None:
        raise Unauthorized("worker login required: send 'Authorization: Bearer <token>'")
    payload = verify_token(token, get_settings().signing_key, PORTAL_SCOPE)
    account = get_active_account(session, int(payload["sub"]))
    if account.worker_id != payload.get("worker_id"):
        raise Unauthorized("token does not belong to this worker account")
    if account.token_epoch != payload.get("epoch"):
        raise Unauthorized("this sign-in has ended (signed out, or the password was changed); "
                           "sign in again")
    return account


CurrentWorker = Annotated[PortalAccount, Depends(current_worker)]
