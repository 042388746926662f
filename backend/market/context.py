"""What every marketplace service function receives, and the marketplace's id scheme."""

from __future__ import annotations

import secrets
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy.orm import Session

from backend.config import MarketRequester

_ID_ALPHABET = "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789"
ID_LENGTH = 30  # MTurk's HIT, HIT type and assignment ids are 30 characters of A-Z and 0-9


def new_id(prefix: str = "") -> str:
    """A fresh public id matching the model's EntityId pattern ``^[A-Z0-9]+$``."""
    body = "".join(secrets.choice(_ID_ALPHABET) for _ in range(ID_LENGTH - len(prefix)))
    return prefix + body


@dataclass
class Call:
    """One requester API call: its unit of work, its caller and its moment.

    ``now`` is read once from the marketplace clock so every rule in the call sees one time.
    """

    session: Session
    requester: MarketRequester
    request_id: str
    now: datetime

    @property
    def requester_id(self) -> str:
        return self.requester.access_key


def epoch(value: datetime | None) -> float | None:
    """A datetime as the JSON protocol's timestamp: seconds since the epoch."""
    return None if value is None else round(value.timestamp(), 3)
