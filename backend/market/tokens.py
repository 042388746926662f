"""UniqueRequestToken bookkeeping: a token replays nothing within 24 hours of its first use.

MTurk documents that tokens expire after 24 hours; a token reused later starts afresh.
"""

from __future__ import annotations

from datetime import timedelta

from sqlalchemy import select

from backend.market.context import Call
from backend.market.errors import DUPLICATE_REQUEST, RequestError
from backend.market.models import RequestToken

TOKEN_LIFETIME = timedelta(hours=24)


def _row(call: Call, operation: str, token: str) -> RequestToken | None:
    stmt = select(RequestToken).where(
        RequestToken.requester == call.requester_id, RequestToken.operation == operation,
        RequestToken.token == token)
    return call.session.scalars(stmt).one_or_none()


def find(call: Call, operation: str, token: str | None) -> RequestToken | None:
    """The earlier use of ``token`` for ``operation`` if it is still live."""
    if token is None:
        return None
    row = _row(call, operation, token)
    if row is None or row.created_at + TOKEN_LIFETIME <= call.now:
        return None
    return row


def remember(call: Call, operation: str, token: str | None, entity_id: str) -> None:
    """Record that this call used ``token`` and produced ``entity_id``."""
    if token is None:
        return
    row = _row(call, operation, token)
    if row is None:
        row = RequestToken(requester=call.requester_id, operation=operation, token=token)
        call.session.add(row)
    row.request_id = call.request_id
    row.entity_id = entity_id
    row.created_at = call.now
    call.session.flush()


def refuse_replay(call: Call, operation: str, token: str | None) -> None:
    """Answer a replayed token as MTurk documents: an error naming the first request."""
    row = find(call, operation, token)
    if row is not None:
        raise RequestError(
            f'The UniqueRequestToken "{token}" has already been processed by request '
            f"{row.request_id}.", DUPLICATE_REQUEST)
