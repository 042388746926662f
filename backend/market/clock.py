"""The marketplace's clock: the one place that says what time it is for HIT and assignment rules.

Time-driven transitions (a HIT expiring, an accepted assignment abandoned at its deadline, a
submitted one auto-approved at AutoApprovalTime) are evaluated lazily when something reads or
changes the records, against ``now()``. Tests move this clock instead of sleeping. Request
signatures are checked against the real wall clock, never this one.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

_offset = timedelta(0)


def now() -> datetime:
    """Current marketplace time, timezone-aware UTC."""
    return datetime.now(UTC) + _offset


def advance(delta: timedelta | float) -> None:
    """Move the marketplace clock forward by ``delta`` (seconds, or a timedelta)."""
    global _offset
    _offset += delta if isinstance(delta, timedelta) else timedelta(seconds=delta)


def reset() -> None:
    """Back to the wall clock."""
    global _offset
    _offset = timedelta(0)
