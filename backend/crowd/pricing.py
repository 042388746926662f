"""Money on the crowd's wire: integer cents inside, decimal strings ("0.50") in requests and
replies, in the provider's currency. Each provider's fees are its ``FeeSchedule``
(``CrowdProvider.fees()``; MTurk's in ``backend.crowd.providers.mturk``).
"""

from __future__ import annotations

from decimal import Decimal


def dollars_to_cents(amount: str | Decimal) -> int:
    """'0.50' -> 50; refuses fractions of a cent."""
    value = Decimal(str(amount)) * 100
    if value != value.to_integral_value() or value < 0:
        raise ValueError(f"{amount} is not a non-negative dollar amount in whole cents")
    return int(value)


def cents_to_dollars(cents: int) -> str:
    """50 -> '0.50', the string form MTurk's Reward and BonusAmount fields take."""
    return f"{cents // 100}.{cents % 100:02d}"


def fee_cents(amount_cents: int, assignments: int = 1) -> int:
    """MTurk's commission on one assignment's reward (or on one bonus, ``assignments=1``): the
    mturk provider's fee schedule, for callers that price MTurk work without a provider."""
    from backend.crowd.providers.mturk import FEES

    return max(FEES.reward_fee_cents(amount_cents, assignments), FEES.min_fee_cents)
