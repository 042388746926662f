from __future__ import annotations

from fastapi import APIRouter

from backend.accounts import service
from backend.accounts.deps import CurrentAdmin, current_admin
from backend.accounts.routes import add_sign_in_routes
from backend.accounts.schemas import AdminRead, TokenRead
from backend.accounts.service import ADMIN

router = APIRouter(prefix="/api/auth", tags=["auth"])


def _token_read(admin_id: int, token_epoch: int, _: str | None) -> TokenRead:
    return TokenRead(access_token=service.account_token(ADMIN, admin_id, token_epoch),
                     expires_in=ADMIN.ttl_s)


add_sign_in_routes(router, ADMIN, login_path="/token", holder="admin",
                   current_account=current_admin, token_model=TokenRead, token_reply=_token_read)


@router.get("/me", response_model=AdminRead)
def me(admin: CurrentAdmin) -> AdminRead:
    return AdminRead(id=admin.id, email=admin.email)
