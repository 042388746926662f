"""The sign-in routes every role has (log in, log out, change the password), added to the
role's own router: admins' under /api/auth, portal workers' under /api/portal.

This module leaves its annotations unpostponed (no ``from __future__ import annotations``):
FastAPI reads each route's account dependency from its annotation, and that dependency is the
role's, known only when the routes are added.
"""

from collections.abc import Callable
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request, Response

from backend.accounts import service
from backend.accounts.models import AccountColumns
from backend.accounts.schemas import LoginRequest, PasswordChange, TokenRead
from backend.accounts.service import Role
from backend.db import SessionDep

# The reply to a login or a password change: (account id, token epoch, worker id) -> token.
TokenReply = Callable[[int, int, str | None], TokenRead]


def add_sign_in_routes(router: APIRouter, role: Role, *, login_path: str, holder: str,
                       current_account: Callable[..., Any], token_model: type[TokenRead],
                       token_reply: TokenReply) -> None:
    """Adds ``login_path``, /logout and /password to ``router`` for accounts of ``role``;
    ``holder`` names the account in the logout route's description ("admin")."""
    account_dep = Depends(current_account)

    @router.post(login_path, response_model=token_model)
    async def login(body: LoginRequest, request: Request) -> TokenRead:
        """A bearer token for 12 hours. Failed logins are limited per account and per client
        address: past the limit every login answers 429 with Retry-After."""
        record = await service.sign_in(request, role, body.email, body.password)
        return token_reply(record.account_id, record.token_epoch, record.worker_id)

    @router.post("/logout", status_code=204, response_class=Response,
                 description=f"Ends every token of this {holder} (on every device).")
    def logout(account: Annotated[AccountColumns, account_dep], session: SessionDep) -> Response:
        service.sign_out(session, account)
        return Response(status_code=204)

    @router.post("/password", response_model=token_model)
    async def change_password(body: PasswordChange, request: Request,
                              account: Annotated[AccountColumns, account_dep],
                              session: SessionDep) -> TokenRead:
        """A new password: every token issued before ends; the reply is a new token."""
        await service.new_password(request, role, session, account, body.current_password,
                                   body.new_password)
        return token_reply(account.id, account.token_epoch,
                           role.claims(account).get("worker_id"))
