"""Bonuses and the account balance."""

from __future__ import annotations

from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import selectinload

from backend.market import ledger, tokens
from backend.market.assignments import get_assignment_or_raise
from backend.market.context import Call
from backend.market.errors import invalid
from backend.market.hits import get_hit_or_raise
from backend.market.models import Bonus, MarketAssignment
from backend.market.money import bonus_cost, format_amount, parse_amount
from backend.market.pagination import page

MAX_REASON = 4096


def send_bonus(call: Call, params: dict[str, Any]) -> Bonus:
    """Pay ``WorkerId`` a bonus for their assignment, plus MTurk's fee, from the balance.

    A UniqueRequestToken already used within 24 hours is refused with the first request's id,
    so a retried call never pays twice.
    """
    token = params.get("UniqueRequestToken")
    tokens.refuse_replay(call, "SendBonus", token)
    amount = parse_amount(params["BonusAmount"], "BonusAmount")
    if amount <= 0:
        raise invalid("BonusAmount must be more than 0.00")
    reason = params["Reason"]
    if not reason.strip() or len(reason) > MAX_REASON:
        raise invalid(f"Reason must be 1 to {MAX_REASON} characters: the worker sees it")
    assignment, _ = get_assignment_or_raise(call, params["AssignmentId"])
    if assignment.worker_id != params["WorkerId"]:
        raise invalid(f"Assignment {assignment.assignment_id} was not worked by "
                      f"{params['WorkerId']}; a bonus goes to the assignment's worker")
    cost = bonus_cost(amount)
    ledger.require_funds(call.session, call.requester, cost,
                         f"a bonus of ${format_amount(amount)}")
    bonus = Bonus(requester=call.requester_id, worker_id=assignment.worker_id,
                  assignment=assignment, amount_cents=amount, reason=reason,
                  grant_time=call.now)
    call.session.add(bonus)
    call.session.flush()
    ledger.record(call.session, call.requester_id, "bonus", call.now, available=-cost,
                  assignment=assignment, bonus=bonus)
    tokens.remember(call, "SendBonus", token, str(bonus.id))
    return bonus


def list_bonus_payments(call: Call, params: dict[str, Any]) -> tuple[list[Bonus], str | None]:
    """Bonuses paid for one assignment, or for every assignment of one HIT."""
    if params.get("HITId") is None and params.get("AssignmentId") is None:
        raise invalid("ListBonusPayments needs a HITId or an AssignmentId")
    stmt = (select(Bonus).join(Bonus.assignment)
            .options(selectinload(Bonus.assignment)))
    if params.get("AssignmentId") is not None:
        assignment, _ = get_assignment_or_raise(call, params["AssignmentId"])
        stmt = stmt.where(Bonus.assignment_pk == assignment.id)
    if params.get("HITId") is not None:
        hit, _ = get_hit_or_raise(call, params["HITId"])
        stmt = stmt.where(MarketAssignment.hit_pk == hit.id)
    return page(call.session, stmt, Bonus.id, "ListBonusPayments", params)


def account_balance(call: Call) -> dict[str, str]:
    available, held = ledger.balances(call.session, call.requester)
    return {"AvailableBalance": format_amount(available), "OnHoldBalance": format_amount(held)}
