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

from sqlalchemy import ColumnElement, case, exists, func, select, tuple_
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment, Task
from backend.crowd import pricing
from backend.crowd.models import CrowdHit, CrowdPayment, CrowdSubmission
from backend.crowd.schemas import CostLine, CostsRead

FIELDS = ("spent_rewards", "spent_bonuses", "spent_fees",
          "committed_rewards", "committed_bonuses", "committed_fees")
_Totals = dict[str, list[int]]  # key -> cents in the order of FIELDS
_DECISIONS = ("approval", "rejection")

# Each sum is taken by the database (one grouped query per kind of money, whatever the size of
# the project); only the groups come back.


def _add(totals: _Totals, key: str, **cents: int) -> None:
    entry = totals.setdefault(key, [0] * len(FIELDS))
    for name, value in cents.items():
        entry[FIELDS.index(name)] += value


def _payment_parts(kind: str, state: str, amount: int, fee: int) -> dict[str, int]:
    if kind == "rejection":
        return {}  # costs nothing, but the worker and sequence are listed
    if kind == "approval":
        return {"spent_rewards": amount, "spent_fees": fee}
    if state == "done":
        return {"spent_bonuses": amount, "spent_fees": fee}
    return {"committed_bonuses": amount, "committed_fees": fee}


def _payments(session: Session, by_sequence: _Totals, by_worker: _Totals) -> None:
    """Ledger sums per sequence and per worker in one pass (two grouping sets)."""
    if session.get_bind().dialect.name != "postgresql":
        # SQLite has no grouping sets: the two groupings one after the other.
        _payments_each(session, by_sequence, by_worker)
        return
    sequence_id, worker_id = Task.sequence_id, CrowdPayment.worker_id
    stmt = (select(sequence_id, worker_id, func.grouping(sequence_id), CrowdPayment.kind,
                   CrowdPayment.state, func.sum(CrowdPayment.amount_cents),
                   func.sum(CrowdPayment.fee_cents))
            .join(Assignment, Assignment.id == CrowdPayment.assignment_id)
            .join(Task, Task.id == Assignment.task_id)
            .group_by(func.grouping_sets(
                tuple_(sequence_id, CrowdPayment.kind, CrowdPayment.state),
                tuple_(worker_id, CrowdPayment.kind, CrowdPayment.state))))
    for seq, worker, no_sequence, kind, state, amount, fee in session.execute(stmt):
        parts = _payment_parts(kind, state, int(amount), int(fee))
        if no_sequence:
            _add(by_worker, worker, **parts)
        else:
            _add(by_sequence, str(seq), **parts)


def _payments_each(session: Session, by_sequence: _Totals, by_worker: _Totals) -> None:
    for key, totals in ((Task.sequence_id, by_sequence), (CrowdPayment.worker_id, by_worker)):
        stmt = (select(key, CrowdPayment.kind, CrowdPayment.state,
                       func.sum(CrowdPayment.amount_cents), func.sum(CrowdPayment.fee_cents))
                .join(Assignment, Assignment.id == CrowdPayment.assignment_id)
                .join(Task, Task.id == Assignment.task_id)
                .group_by(key, CrowdPayment.kind, CrowdPayment.state))
        for value, kind, state, amount, fee in session.execute(stmt):
            _add(totals, str(value), **_payment_parts(kind, state, int(amount), int(fee)))


def _undecided() -> ColumnElement[bool]:
    """The condition "this submission has no approval or rejection yet"."""
    return ~exists().where(CrowdPayment.assignment_id == CrowdSubmission.assignment_id,
                           CrowdPayment.kind.in_(_DECISIONS))


def _held(session: Session, by_sequence: _Totals, by_worker: _Totals) -> None:
    """Money still held: per sequence, every HIT's open slots (an expired HIT's: its waiting
    submissions); per worker, their submitted work not decided yet."""
    decided = (select(Assignment.hit_id.label("hit_id"), func.count().label("n"))
               .join(CrowdPayment, CrowdPayment.assignment_id == Assignment.id)
               .where(CrowdPayment.kind.in_(_DECISIONS))
               .group_by(Assignment.hit_id).subquery())
    waiting = (select(CrowdSubmission.hit_id.label("hit_id"), func.count().label("n"))
               .where(_undecided()).group_by(CrowdSubmission.hit_id).subquery())
    # Two-argument max is SQLite's greatest.
    greatest = func.greatest if session.get_bind().dialect.name == "postgresql" else func.max
    slots = case(
        (CrowdHit.expired_at.is_not(None), func.coalesce(waiting.c.n, 0)),
        else_=greatest(CrowdHit.max_assignments - func.coalesce(decided.c.n, 0), 0))
    per_sequence = (
        select(Task.sequence_id, CrowdHit.reward_cents, CrowdHit.max_assignments,
               func.sum(slots))
        .join(Task, Task.id == CrowdHit.task_id)
        .outerjoin(decided, decided.c.hit_id == CrowdHit.hit_id)
        .outerjoin(waiting, waiting.c.hit_id == CrowdHit.hit_id)
        .where(CrowdHit.hit_id.is_not(None))
        .group_by(Task.sequence_id, CrowdHit.reward_cents, CrowdHit.max_assignments))
    for sequence_id, reward, max_assignments, open_slots in session.execute(per_sequence):
        fee = pricing.fee_cents(reward, max_assignments)
        n = int(open_slots or 0)
        _add(by_sequence, str(sequence_id), committed_rewards=n * reward,
             committed_fees=n * fee)
    per_worker = (
        select(CrowdSubmission.worker_id, CrowdHit.reward_cents, CrowdHit.max_assignments,
               func.count())
        .join(CrowdHit, CrowdHit.hit_id == CrowdSubmission.hit_id)
        .where(_undecided())
        .group_by(CrowdSubmission.worker_id, CrowdHit.reward_cents, CrowdHit.max_assignments))
    for worker_id, reward, max_assignments, n in session.execute(per_worker):
        fee = pricing.fee_cents(reward, max_assignments)
        _add(by_worker, worker_id, committed_rewards=n * reward, committed_fees=n * fee)


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
