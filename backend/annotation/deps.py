"""What the worker-facing page routes depend on: the claims of the page's signed token (an
assignment, a task preview or a read-only review) and the assignment it opens."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import Depends, Request

from backend.accounts.deps import BearerCredentials, bearer_token
from backend.annotation import service
from backend.annotation.models import Assignment
from backend.annotation.tokens import ASSIGNMENT_SCOPE, READONLY_SCOPE, TASK_SCOPE
from backend.config import get_settings
from backend.db import SessionDep
from backend.errors import Forbidden, Unauthorized
from backend.security import verify_token


# Both run on the event loop (no thread hop): they only check the token's signature.
async def worker_claims(request: Request, _scheme: BearerCredentials = None) -> dict[str, Any]:
    token = bearer_token(request)
    if token is None:
        raise Unauthorized("this page needs the token from its link (Authorization: Bearer)")
    return verify_token(token, get_settings().signing_key,
                        (ASSIGNMENT_SCOPE, TASK_SCOPE, READONLY_SCOPE))


async def writer_claims(claims: Annotated[dict[str, Any], Depends(worker_claims)]
                   ) -> dict[str, Any]:
    """The claims of a token that may change labels (checked before the body is read)."""
    if claims["scope"] == READONLY_SCOPE:
        raise Forbidden("a read-only review link cannot save or submit labels")
    return claims


WorkerClaims = Annotated[dict[str, Any], Depends(worker_claims)]
WriterClaims = Annotated[dict[str, Any], Depends(writer_claims)]


def assignment_id_of(claims: dict[str, Any]) -> int:
    if claims["scope"] != ASSIGNMENT_SCOPE:
        raise Unauthorized("a preview link cannot change labels; accept the HIT first")
    return int(claims["assignment_id"])


def assignment_of(session: SessionDep, claims: dict[str, Any]) -> Assignment:
    return service.get_assignment_or_raise(session, assignment_id_of(claims))
