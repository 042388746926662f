"""Spend so far and money committed, from our own ledger, in US cents.

Spent: approved rewards and bonuses with their MTurk fees. Committed: the reward and fee still
held for assignments not decided yet (every open slot of a published HIT counts, as MTurk holds
it from the balance at publish time).
"""

from __future__ import annotations

from collections import defaultdict

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment, Task
from backend.crowd import pricing
from backend.crowd.models import CrowdHit, CrowdPayment, CrowdSubmission
from backend.crowd.schemas import CostLine, CostsRead

_Totals = dict[str, list[int]]  # key -> [spent, committed]


def _add(totals: _Totals, key: str, spent: int = 0, committed: int = 0) -> None:
    entry = totals.setdefault(key, [0, 0])
    entry[0] += spent
    entry[1] += committed


def _spent(session: Session, by_sequence: _Totals, by_worker: _Totals) -> None:
    stmt = (select(CrowdPayment, Task.sequence_id)
            .join(Assignment, Assignment.id == CrowdPayment.assignment_id)
            .join(Task, Task.id == Assignment.task_id)
            .where(CrowdPayment.kind != "rejection"))
    for payment, sequence_id in session.execute(stmt):
        cost = payment.amount_cents + payment.fee_cents
        _add(by_sequence, str(sequence_id), spent=cost)
        _add(by_worker, payment.worker_id, spent=cost)


def _decided_per_hit(session: Session) -> dict[str, int]:
    stmt = (select(Assignment.hit_id)
            .join(CrowdPayment, CrowdPayment.assignment_id == Assignment.id)
            .where(CrowdPayment.kind.in_(("approval", "rejection"))))
    counts: dict[str, int] = defaultdict(int)
    for hit_id in session.scalars(stmt):
        counts[hit_id or ""] += 1
    return counts


def _committed(session: Session, by_sequence: _Totals, by_worker: _Totals) -> None:
    decided = _decided_per_hit(session)
    hits = session.execute(select(CrowdHit, Task.sequence_id)
                           .join(Task, Task.id == CrowdHit.task_id)
                           .where(CrowdHit.hit_id.is_not(None)))
    per_assignment: dict[str, int] = {}
    for hit, sequence_id in hits:
        each = hit.reward_cents + pricing.fee_cents(hit.reward_cents, hit.max_assignments)
        per_assignment[hit.hit_id or ""] = each
        open_slots = max(hit.max_assignments - decided.get(hit.hit_id or "", 0), 0)
        _add(by_sequence, str(sequence_id), committed=open_slots * each)
    decided_ids = select(CrowdPayment.assignment_id).where(
        CrowdPayment.kind.in_(("approval", "rejection")))
    undecided = select(CrowdSubmission).where(CrowdSubmission.assignment_id.not_in(decided_ids))
    for submission in session.scalars(undecided):
        _add(by_worker, submission.worker_id, committed=per_assignment.get(submission.hit_id, 0))


def _lines(totals: _Totals) -> list[CostLine]:
    return [CostLine(key=key, spent=pricing.cents_to_dollars(spent),
                     committed=pricing.cents_to_dollars(committed))
            for key, (spent, committed) in sorted(totals.items())]


def costs(session: Session) -> CostsRead:
    """Spend and commitments for the project, per sequence (by id) and per worker."""
    by_sequence: _Totals = {}
    by_worker: _Totals = {}
    _spent(session, by_sequence, by_worker)
    _committed(session, by_sequence, by_worker)
    spent = sum(v[0] for v in by_sequence.values())
    committed = sum(v[1] for v in by_sequence.values())
    total = CostLine(key="project", spent=pricing.cents_to_dollars(spent),
                     committed=pricing.cents_to_dollars(committed))
    return CostsRead(total=total, by_sequence=_lines(by_sequence), by_worker=_lines(by_worker))
