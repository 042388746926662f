"""MTurk's price rules, in integer US cents.

MTurk charges a 20% commission on rewards and bonuses, 20% more (40% in all) on the rewards of
HITs with 10 or more assignments, and at least $0.01 per assignment or bonus.
"""

from __future__ import annotations

from dataclasses import dataclass
from decimal import ROUND_HALF_UP, Decimal

BASE_FEE = Decimal("0.20")
LARGE_HIT_FEE = Decimal("0.40")
LARGE_HIT_ASSIGNMENTS = 10
MIN_FEE_CENTS = 1


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
    """MTurk's commission on one assignment's reward (or on one bonus, ``assignments=1``)."""
    rate = LARGE_HIT_FEE if assignments >= LARGE_HIT_ASSIGNMENTS else BASE_FEE
    fee = (Decimal(amount_cents) * rate).quantize(Decimal(1), rounding=ROUND_HALF_UP)
    return max(int(fee), MIN_FEE_CENTS)


@dataclass(frozen=True)
class HitCost:
    """What publishing HITs of one shape costs when every assignment is approved."""

    hits: int
    assignments_per_hit: int
    reward_cents: int
    fee_cents_per_assignment: int

    @property
    def rewards_cents(self) -> int:
        return self.hits * self.assignments_per_hit * self.reward_cents

    @property
    def fees_cents(self) -> int:
        return self.hits * self.assignments_per_hit * self.fee_cents_per_assignment

    @property
    def total_cents(self) -> int:
        return self.rewards_cents + self.fees_cents


def estimate(hits: int, assignments_per_hit: int, reward_cents: int) -> HitCost:
    return HitCost(hits, assignments_per_hit, reward_cents,
                   fee_cents(reward_cents, assignments_per_hit))
