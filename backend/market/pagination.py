"""NextToken / MaxResults paging, keyset on the integer primary key (stable under inserts)."""

from __future__ import annotations

import base64
import binascii
import json
from typing import Any, TypeVar

from sqlalchemy import Select
from sqlalchemy.orm import InstrumentedAttribute, Session

from backend.market.errors import invalid

T = TypeVar("T")
DEFAULT_MAX_RESULTS = 10


def encode(operation: str, after_pk: int) -> str:
    raw = json.dumps({"op": operation, "after": after_pk}, separators=(",", ":")).encode()
    return base64.urlsafe_b64encode(raw).decode()


def decode(operation: str, token: str | None) -> int:
    """The primary key a NextToken continues after (0 without a token)."""
    if token is None:
        return 0
    try:
        data: Any = json.loads(base64.urlsafe_b64decode(token.encode()))
        after = data["after"] if data.get("op") == operation else None
    except (ValueError, TypeError, KeyError, AttributeError, binascii.Error):
        after = None
    if not isinstance(after, int) or isinstance(after, bool) or after < 0:
        raise invalid(f"NextToken is not a token that {operation} returned")
    return after


def page_size(params: dict[str, Any]) -> int:
    return int(params.get("MaxResults") or DEFAULT_MAX_RESULTS)


def page(
    session: Session, stmt: Select[T], pk: InstrumentedAttribute[int],
    operation: str, params: dict[str, Any],
) -> tuple[list[T], str | None]:
    """One page of ``stmt`` and the NextToken of the rest (None on the last page)."""
    size = page_size(params)
    after = decode(operation, params.get("NextToken"))
    rows = list(session.scalars(stmt.where(pk > after).order_by(pk).limit(size + 1)))
    if len(rows) <= size:
        return rows, None
    rows = rows[:size]
    return rows, encode(operation, getattr(rows[-1], pk.key))


def page_result(key: str, rows: list[dict[str, Any]], next_token: str | None) -> dict[str, Any]:
    """The wire form shared by every List operation."""
    result: dict[str, Any] = {"NumResults": len(rows), key: rows}
    if next_token is not None:
        result["NextToken"] = next_token
    return result
