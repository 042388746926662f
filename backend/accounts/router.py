from __future__ import annotations

from fastapi import APIRouter, Request, Response

from backend.accounts import service
from backend.accounts.deps import CurrentAdmin
from backend.accounts.schemas import AdminRead, LoginRequest, PasswordChange, TokenRead
from backend.accounts.service import ADMIN
from backend.db import SessionDep

router = APIRouter(prefix="/api/auth", tags=["auth"])



def _token_read(admin_id: int, token_epoch: int) -> TokenRead:
    return TokenRead(access_token=service.account_token(ADMIN, admin_id, token_epoch),
                     expires_in=ADMIN.ttl_s)


@router.post("/token", response_model=TokenRead)
async def login(body: LoginRequest, request: Request) -> TokenRead:
    """A bearer token for 12 hours. Failed logins are limited per account and per client
    address: past the limit every login answers 429 with Retry-After."""
    record = await service.sign_in(request, ADMIN, body.email, body.password)
    return _token_read(record.account_id, record.token_epoch)


@router.post("/logout", status_code=204, response_class=Response)
def logout(admin: CurrentAdmin, session: SessionDep) -> Response:
    """Ends every token of this admin (on every device)."""
    service.sign_out(session, admin)
    return Response(status_code=204)


@router.post("/password", response_model=TokenRead)
async def change_password(body: PasswordChange, request: Request, admin: CurrentAdmin,
                          session: SessionDep) -> TokenRead:
    """A new password: every token issued before ends; the reply is a new token."""
    await service.new_password(request, ADMIN, session, admin, body.current_password,
                               body.new_password)
    return _token_read(admin.id, admin.token_epoch)


@router.get("/me", response_model=AdminRead)
def me(admin: CurrentAdmin) -> AdminRead:
    return AdminRead(id=admin.id, email=admin.email)
