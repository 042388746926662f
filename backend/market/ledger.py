"""The requester's money: ledger entries, balances and the funds check.

Available balance = the account's starting balance + the sum of ``available_cents``; the amount
on hold for outstanding assignments = the sum of ``held_cents``. Like MTurk, a HIT's rewards
and fees are held when it is published (so a requester cannot publish more than it can pay),
paid on approval, and given back on rejection or when the HIT closes with slots unfilled.
"""

from __future__ import annotations

import hashlib
from datetime import datetime

from sqlalchemy import func, select, text
from sqlalchemy.orm import Session

from backend.config import MarketRequester
from backend.market.errors import INSUFFICIENT_FUNDS, RequestError
from backend.market.models import Bonus, Hit, LedgerEntry, MarketAssignment
from backend.market.money import assignment_cost, format_amount


def record(
    session: Session, hit_or_requester: Hit | str, kind: str, now: datetime, *,
    available: int = 0, held: int = 0, assignment: MarketAssignment | None = None,
    bonus: Bonus | None = None,
) -> LedgerEntry:
    hit = hit_or_requester if isinstance(hit_or_requester, Hit) else None
    requester = hit.requester if hit is not None else str(hit_or_requester)
    entry = LedgerEntry(
        requester=requester, kind=kind, available_cents=available, held_cents=held,
        hit_pk=hit.id if hit is not None else None,
        assignment_pk=assignment.id if assignment is not None else None,
        bonus_pk=bonus.id if bonus is not None else None, created_at=now)
    session.add(entry)
    return entry


def lock_requester(session: Session, requester: str) -> None:
    """Serialise one requester's calls, so a funds check sees every spend before it.

    PostgreSQL: a transaction-scoped advisory lock per requester. SQLite has a single writer:
    any write statement takes the database's write lock until the transaction ends.
    """
    dialect = session.get_bind().dialect.name
    if dialect == "postgresql":
        key = int.from_bytes(hashlib.sha256(requester.encode()).digest()[:8], "big", signed=True)
        session.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": key})
    elif dialect == "sqlite":
        session.execute(text("UPDATE market_ledger SET id = id WHERE 1 = 0"))


def balances(session: Session, requester: MarketRequester) -> tuple[int, int]:
    """(available, on hold) in cents."""
    session.flush()
    stmt = select(func.coalesce(func.sum(LedgerEntry.available_cents), 0),
                  func.coalesce(func.sum(LedgerEntry.held_cents), 0)
                  ).where(LedgerEntry.requester == requester.access_key)
    spent, held = session.execute(stmt).one()
    return requester.start_balance_cents + int(spent), int(held)


def require_funds(session: Session, requester: MarketRequester, cost_cents: int, what: str) -> None:
    """Refuse a spend the available balance cannot cover, as MTurk does."""
    available, _ = balances(session, requester)
    if cost_cents > available:
        raise RequestError(
            f"Insufficient funds: {what} costs ${format_amount(cost_cents)} (rewards or bonus "
            f"plus fees) and the available balance is ${format_amount(available)}.",
            INSUFFICIENT_FUNDS)


def unit_cost(hit: Hit) -> int:
    """Reward plus fee of one assignment of ``hit``; nothing for a HIT that pays nothing
    (only an unpaid account's HITs may: the team crowd's, which holds and pays no money)."""
    reward = hit.hit_type.reward_cents
    return assignment_cost(reward, hit.max_assignments) if reward else 0


def hold_slots(
    session: Session, hit: Hit, target_slots: int, now: datetime,
    payer: MarketRequester | None = None,
) -> None:
    """Hold reward and fee for exactly ``target_slots`` assignments of ``hit``.

    Raising the hold spends available balance and, with ``payer``, is refused when the balance
    cannot cover it; lowering it gives the money back.
    """
    delta = target_slots - hit.held_slots
    if delta == 0:
        return
    cost = delta * unit_cost(hit)
    if delta > 0 and payer is not None:
        require_funds(session, payer, cost, f"holding {delta} assignment(s) of HIT {hit.hit_id}")
    record(session, hit, "hold" if delta > 0 else "release", now, available=-cost, held=cost)
    hit.held_slots = target_slots


def pay_from_hold(session: Session, assignment: MarketAssignment, now: datetime) -> None:
    """Pay a submitted assignment's reward and fee out of its HIT's hold."""
    hit = assignment.hit
    cost = unit_cost(hit)
    record(session, hit, "pay", now, held=-cost, assignment=assignment)
    hit.held_slots -= 1


def pay_directly(
    session: Session, requester: MarketRequester, assignment: MarketAssignment, now: datetime
) -> None:
    """Pay an assignment whose hold was already given back (approval overriding a rejection)."""
    hit = assignment.hit
    cost = unit_cost(hit)
    require_funds(session, requester, cost, f"approving assignment {assignment.assignment_id}")
    record(session, hit, "pay", now, available=-cost, assignment=assignment)
