"""Spend so far and money committed, from our own ledger, in US cents; rewards, bonuses and
MTurk's fees apart, for the project (the whole database), per sequence and per worker.

Spent: approved rewards and paid bonuses with their fees; a rejection costs nothing.
Committed: what is still held. Every open slot of a live HIT (MTurk holds reward + fee from the
balance at publish time; an expired HIT takes no more work, so only its submitted, undecided
assignments stay held), and bonuses whose ledger row is still pending (started, not yet
confirmed paid). Open slots belong to no worker yet: a worker's committed money is their
submitted, undecided assignments and pending bonuses, so the per-worker lines need not add up
to the project's committed total.
"""

from __future__ import annotations

from collections import defaultdict

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment, Task
from backend.crowd import pricing
from backend.crowd.models import CrowdHit, CrowdPayment, CrowdSubmission
from backend.crowd.schemas import CostLine, CostsRead

FIELDS = ("spent_rewards", "spent_bonuses", "spent_fees",
          "committed_rewards", "committed_bonuses", "committed_fees")
_Totals = dict[str, list[int]]  # key -> cents in the order of FIELDS
_DECISIONS = ("approval", "rejection")


def _add(totals: _Totals, key: str, **cents: int) -> None:
    entry = totals.setdefault(key, [0] * len(FIELDS))
    for name, value in cents.items():
        entry[FIELDS.index(name)] += value


def _payment_parts(payment: CrowdPayment) -> dict[str, int]:
    if payment.kind == "rejection":
        return {}  # costs nothing, but the worker and sequence are listed
    if payment.kind == "approval":
        return {"spent_rewards": payment.amount_cents, "spent_fees": payment.fee_cents}
    if payment.state == "done":
        return {"spent_bonuses": payment.amount_cents, "spent_fees": payment.fee_cents}
    return {"committed_bonuses": payment.amount_cents, "committed_fees": payment.fee_cents}


def _payments(session: Session, by_sequence: _Totals, by_worker: _Totals) -> None:
    stmt = (select(CrowdPayment, Task.sequence_id)
            .join(Assignment, Assignment.id == CrowdPayment.assignment_id)
            .join(Task, Task.id == Assignment.task_id))
    for payment, sequence_id in session.execute(stmt):
        parts = _payment_parts(payment)
        _add(by_sequence, str(sequence_id), **parts)
        _add(by_worker, payment.worker_id, **parts)


def _decided_per_hit(session: Session) -> dict[str, int]:
    stmt = (select(Assignment.hit_id)
            .join(CrowdPayment, CrowdPayment.assignment_id == Assignment.id)
            .where(CrowdPayment.kind.in_(_DECISIONS)))
    counts: dict[str, int] = defaultdict(int)
    for hit_id in session.scalars(stmt):
        counts[hit_id or ""] += 1
    return counts


def _waiting_per_hit(session: Session) -> dict[str, list[CrowdSubmission]]:
    """Verified submissions with no approval or rejection yet, by HIT id."""
    decided_ids = select(CrowdPayment.assignment_id).where(CrowdPayment.kind.in_(_DECISIONS))
    waiting: dict[str, list[CrowdSubmission]] = defaultdict(list)
    for submission in session.scalars(
            select(CrowdSubmission).where(CrowdSubmission.assignment_id.not_in(decided_ids))):
        waiting[submission.hit_id].append(submission)
    return waiting


def _held(session: Session, by_sequence: _Totals, by_worker: _Totals) -> None:
    decided, waiting = _decided_per_hit(session), _waiting_per_hit(session)
    hits = session.execute(select(CrowdHit, Task.sequence_id)
                           .join(Task, Task.id == CrowdHit.task_id)
                           .where(CrowdHit.hit_id.is_not(None)))
    for hit, sequence_id in hits:
        reward = hit.reward_cents
        fee = pricing.fee_cents(reward, hit.max_assignments)
        submitted = waiting.get(hit.hit_id or "", [])
        for submission in submitted:
            _add(by_worker, submission.worker_id, committed_rewards=reward, committed_fees=fee)
        if hit.expired_at is not None:
            slots = len(submitted)
        else:
            slots = max(hit.max_assignments - decided.get(hit.hit_id or "", 0), 0)
        _add(by_sequence, str(sequence_id), committed_rewards=slots * reward,
             committed_fees=slots * fee)


def _line(key: str, cents: list[int]) -> CostLine:
    money = pricing.cents_to_dollars
    parts = {name: money(value) for name, value in zip(FIELDS, cents, strict=True)}
    return CostLine(key=key, spent=money(sum(cents[:3])), committed=money(sum(cents[3:])),
                    **parts)


def costs(session: Session) -> CostsRead:
    """Spend and commitments for the project, per sequence (keyed by id) and per worker."""
    by_sequence: _Totals = {}
    by_worker: _Totals = {}
    _payments(session, by_sequence, by_worker)
    _held(session, by_sequence, by_worker)
    total = [sum(column) for column in zip(*by_sequence.values(), strict=True)] \
        or [0] * len(FIELDS)
    return CostsRead(total=_line("project", total),
                     by_sequence=[_line(k, by_sequence[k]) for k in sorted(by_sequence, key=int)],
                     by_worker=[_line(k, v) for k, v in sorted(by_worker.items())])
