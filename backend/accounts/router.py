from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel, Field

from backend.accounts.deps import ADMIN_SCOPE, CurrentAdmin
from backend.accounts.service import authenticate
from backend.config import get_settings
from backend.db import SessionDep
from backend.security import sign_token

router = APIRouter(prefix="/api/auth", tags=["auth"])

ADMIN_TOKEN_TTL_S = 12 * 3600


class LoginRequest(BaseModel):
    email: str = Field(min_length=3, max_length=320)
    password: str = Field(min_length=1, max_length=1000)


class TokenRead(BaseModel):
    access_token: str
    token_type: str = "bearer"
    expires_in: int


class AdminRead(BaseModel):
    id: int
    email: str


@router.post("/token", response_model=TokenRead)
def login(body: LoginRequest, session: SessionDep) -> TokenRead:
    admin = authenticate(session, body.email, body.password)
    token = sign_token({"scope": ADMIN_SCOPE, "sub": admin.id}, get_settings().secret_key,
                       ADMIN_TOKEN_TTL_S)
    return TokenRead(access_token=token, expires_in=ADMIN_TOKEN_TTL_S)


@router.get("/me", response_model=AdminRead)
def me(admin: CurrentAdmin) -> AdminRead:
    return AdminRead(id=admin.id, email=admin.email)
