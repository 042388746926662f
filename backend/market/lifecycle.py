"""Time-driven state of HITs and assignments, evaluated lazily against the marketplace clock.

HIT status: Assignable while open (not expired, not deleted) with a free slot; Unassignable
while a worker still holds an accepted assignment and no slot is free; otherwise Reviewable
(every assignment submitted, or the HIT expired), or Reviewing when the requester marked it so;
Disposed once deleted. An accepted assignment not submitted by its deadline is Abandoned and
frees its slot; a submitted one not reviewed by its AutoApprovalTime is Approved and paid.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import select
from sqlalchemy.orm import Session, selectinload

from backend.config import MarketRequester
from backend.market import ledger
from backend.market.models import Hit, MarketAssignment

# Statuses that occupy one of a HIT's MaxAssignments slots.
OCCUPYING = ("Accepted", "Submitted", "Approved", "Rejected")


@dataclass(frozen=True)
class HitState:
    status: str
    pending: int  # accepted and still within their deadline
    available: int
    submitted: int
    completed: int  # approved or rejected


def is_open(hit: Hit, now: datetime) -> bool:
    return hit.disposed_at is None and hit.expiration > now


def hit_state(hit: Hit, now: datetime) -> HitState:
    """The HIT's state from its assignments as they stand (call ``refresh_hit`` first)."""
    counts = Counter(a.status for a in hit.assignments)
    occupied = sum(counts[s] for s in OCCUPYING)
    open_ = is_open(hit, now)
    available = max(0, hit.max_assignments - occupied) if open_ else 0
    pending = counts["Accepted"]
    if hit.disposed_at is not None:
        status = "Disposed"
    elif available > 0:
        status = "Assignable"
    elif pending > 0:
        status = "Unassignable"
    else:
        status = "Reviewing" if hit.reviewing else "Reviewable"
    return HitState(status, pending, available, counts["Submitted"],
                    counts["Approved"] + counts["Rejected"])


def _apply_due_transitions(session: Session, hit: Hit, now: datetime) -> None:
    for assignment in hit.assignments:
        if assignment.status == "Accepted" and assignment.deadline <= now:
            assignment.status = "Abandoned"
        elif (assignment.status == "Submitted" and assignment.auto_approval_time is not None
              and assignment.auto_approval_time <= now):
            assignment.status = "Approved"
            assignment.approval_time = assignment.auto_approval_time
            ledger.pay_from_hold(session, assignment, now)


def refresh_hit(
    session: Session, hit: Hit, now: datetime, payer: MarketRequester | None = None
) -> HitState:
    """Apply what the clock has made due, then hold exactly the funds the HIT can still cost.

    ``payer`` is given by requester calls that may raise the hold (publishing, adding
    assignments, extending); the call fails with InsufficientFunds if the balance cannot cover.
    """
    _apply_due_transitions(session, hit, now)
    state = hit_state(hit, now)
    ledger.hold_slots(session, hit, state.pending + state.submitted + state.available, now, payer)
    hit.settled = not is_open(hit, now) and state.pending == 0
    session.flush()
    return state


def load_hits(session: Session, hit_pks: set[int] | list[int]) -> list[Hit]:
    stmt = (select(Hit).where(Hit.id.in_(hit_pks)).order_by(Hit.id)
            .options(selectinload(Hit.assignments), selectinload(Hit.hit_type)))
    return list(session.scalars(stmt))


def settle_due(session: Session, requester: str, now: datetime) -> None:
    """Refresh every HIT of ``requester`` on which the clock has made something due."""
    submitted_due = (select(MarketAssignment.hit_pk).join(Hit).where(
        Hit.requester == requester, MarketAssignment.status == "Submitted",
        MarketAssignment.auto_approval_time <= now))
    abandoned_due = (select(MarketAssignment.hit_pk).join(Hit).where(
        Hit.requester == requester, MarketAssignment.status == "Accepted",
        MarketAssignment.deadline <= now))
    expired_unsettled = select(Hit.id).where(
        Hit.requester == requester, Hit.settled.is_(False), Hit.expiration <= now)
    pks: set[int] = set()
    for stmt in (submitted_due, abandoned_due, expired_unsettled):
        pks.update(session.scalars(stmt))
    if pks:
        for hit in load_hits(session, pks):
            refresh_hit(session, hit, now)
