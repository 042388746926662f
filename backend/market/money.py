"""Money: integer cents inside, MTurk's decimal strings ("0.50") on the wire.

Fees follow MTurk's published pricing: 20% of the reward or bonus, a further 20% of the reward
for HITs with 10 or more assignments, at least $0.01 per assignment or bonus, rounded half up
to the cent.
"""

from __future__ import annotations

import re

from backend.market.errors import invalid

# CurrencyAmount in the service model: digits, an optional point, up to two decimals.
_AMOUNT_RE = re.compile(r"([0-9]+)\.?([0-9]{0,2})")
MAX_AMOUNT_CENTS = 10**12  # $10 billion: far above any real amount, far inside int64
BASE_FEE_PERCENT = 20
LARGE_HIT_FEE_PERCENT = 40
LARGE_HIT_ASSIGNMENTS = 10
MIN_FEE_CENTS = 1


def parse_amount(text: str, member: str) -> int:
    """``"5"``, ``"5."``, ``"5.5"`` or ``"5.50"`` as cents; ``member`` names it in errors."""
    match = _AMOUNT_RE.fullmatch(text)
    if match is None:
        raise invalid(f"{member} {text!r} is not an amount in US dollars like 0.50")
    cents = int(match.group(1)) * 100 + int(match.group(2).ljust(2, "0"))
    if cents > MAX_AMOUNT_CENTS:
        raise invalid(f"{member} {text} is larger than the marketplace allows")
    return cents


def format_amount(cents: int) -> str:
    """Cents as MTurk writes amounts: ``"0.50"``, ``"-1.20"``."""
    sign = "-" if cents < 0 else ""
    whole, frac = divmod(abs(cents), 100)
    return f"{sign}{whole}.{frac:02d}"


def _fee(cents: int, percent: int) -> int:
    # Round half up: amounts are non-negative, so integer arithmetic does it exactly.
    return max(MIN_FEE_CENTS, (cents * percent + 50) // 100)


def assignment_fee(reward_cents: int, max_assignments: int) -> int:
    """MTurk's fee on one assignment's reward."""
    large = max_assignments >= LARGE_HIT_ASSIGNMENTS
    return _fee(reward_cents, LARGE_HIT_FEE_PERCENT if large else BASE_FEE_PERCENT)


def assignment_cost(reward_cents: int, max_assignments: int) -> int:
    """What one approved assignment costs the requester: reward plus fee."""
    return reward_cents + assignment_fee(reward_cents, max_assignments)


def bonus_cost(bonus_cents: int) -> int:
    """What a bonus costs the requester: the bonus plus its 20% fee."""
    return bonus_cents + _fee(bonus_cents, BASE_FEE_PERCENT)
