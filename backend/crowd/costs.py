"""Spend so far and money committed, from our own ledger, in cents; rewards, bonuses and the
providers' fees apart, for the project (the whole database), per sequence, per worker and per
crowd provider (each in its own currency and fees; the project and sequence lines add the
amounts up as they are, which is exact while every provider used shares one currency).

Spent: approved rewards and paid bonuses with their fees; a rejection costs nothing.
Committed: what is still held. Every open slot of a live HIT (MTurk holds reward + fee from the
balance at publish time; an expired HIT takes no more work, so only its submitted, undecided
assignments stay held), and bonuses whose ledger row is still pending (started, not yet
confirmed paid). Open slots belong to no worker yet: a worker's committed money is their
submitted, undecided assignments and pending bonuses, so the per-worker lines need not add up
to the project's committed total. A sequence deleted with its work (a forced delete) keeps
its line, "subject/name (deleted)" under the key "deleted:<id>", from what its ledger held
when it was deleted (crowd_deleted_costs); its workers' lines keep that money too.
"""

from __future__ import annotations

from sqlalchemy import ColumnElement, exists, func, select
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment, Task
from backend.captures.models import Sequence, Subject
from backend.crowd import pricing, totals
from backend.crowd.models import (
    CrowdCostTotal,
    CrowdDeletedCost,
    CrowdHit,
    CrowdPayment,
    CrowdSubmission,
)
from backend.crowd.provider import FeeSchedule
from backend.crowd.providers import fees_of
from backend.crowd.schemas import CostLine, CostsRead

FIELDS = ("spent_rewards", "spent_bonuses", "spent_fees",
          "committed_rewards", "committed_bonuses", "committed_fees")
_Totals = dict[str, list[int]]  # key -> cents in the order of FIELDS
_DECISIONS = ("approval", "rejection")
# HITs of one price within a sequence: (sequence id, provider, reward cents, max assignments).
_Shape = tuple[int, str, int, int]

# The ledger's sums come from crowd_cost_totals (backend.crowd.totals: kept with each payment
# row, a few rows per sequence and per worker), and a live HIT's open slots from its own
# ``decided`` count (max_assignments - decided): two small reads and one grouped pass over the
# HITs and the undecided submissions, whatever the size of the ledger.


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


def _payments(session: Session, scopes: dict[str, _Totals]) -> None:
    """The ledger's sums per sequence, worker and provider, from the running totals."""
    rows = session.execute(select(CrowdCostTotal.scope, CrowdCostTotal.key, CrowdCostTotal.kind,
                                  CrowdCostTotal.state, CrowdCostTotal.amount_cents,
                                  CrowdCostTotal.fee_cents))
    for scope, key, kind, state, amount, fee in rows:
        _add(scopes[scope], key, **_payment_parts(kind, state, int(amount), int(fee)))


class _Fees(dict[str, FeeSchedule]):
    """Each provider's fee schedule, looked up once per report."""

    def __missing__(self, name: str) -> FeeSchedule:
        self[name] = fees_of(name)
        return self[name]


def _undecided() -> ColumnElement[bool]:
    """The condition "this submission has no approval or rejection yet"."""
    return ~exists().where(CrowdPayment.assignment_id == CrowdSubmission.assignment_id,
                           CrowdPayment.kind.in_(_DECISIONS))


def _held(session: Session, scopes: dict[str, _Totals]) -> None:
    """Money still held: per sequence (and provider), every live unit's open places and a
    closed unit's waiting submissions; per worker, their submitted work not decided yet."""
    by_sequence, by_worker, by_provider = scopes["sequence"], scopes["worker"], scopes["provider"]
    fees = _Fees()
    # Only HITs with open slots (ix_crowd_hits_open_task_id, a partial index, holds them) add
    # to the held money.
    shapes = (select(Task.sequence_id, CrowdHit.provider, CrowdHit.reward_cents,
                     CrowdHit.max_assignments,
                     func.sum(CrowdHit.max_assignments - CrowdHit.decided))
              .join(Task, Task.id == CrowdHit.task_id)
              .where(CrowdHit.hit_id.is_not(None), CrowdHit.expired_at.is_(None),
                     CrowdHit.max_assignments > CrowdHit.decided)
              .group_by(Task.sequence_id, CrowdHit.provider, CrowdHit.reward_cents,
                        CrowdHit.max_assignments))
    open_slots: dict[_Shape, int] = {}
    for seq, provider, reward, slots, live_open in session.execute(shapes):
        open_slots[(seq, provider, reward, slots)] = int(live_open)
    waiting = (select(CrowdSubmission.worker_id, Task.sequence_id, CrowdHit.provider,
                      CrowdHit.reward_cents, CrowdHit.max_assignments,
                      CrowdHit.expired_at.is_not(None), func.count())
               .join(CrowdHit, CrowdHit.hit_id == CrowdSubmission.hit_id)
               .join(Task, Task.id == CrowdHit.task_id)
               .where(_undecided())
               .group_by(CrowdSubmission.worker_id, Task.sequence_id, CrowdHit.provider,
                         CrowdHit.reward_cents, CrowdHit.max_assignments,
                         CrowdHit.expired_at.is_not(None)))
    for worker, seq, provider, reward, slots, expired, n in session.execute(waiting):
        fee = fees[provider].reward_fee_cents(reward, slots)
        _add(by_worker, worker, committed_rewards=n * reward, committed_fees=n * fee)
        if expired:  # an expired HIT holds only its submitted, undecided work
            shape = (seq, provider, reward, slots)
            open_slots[shape] = open_slots.get(shape, 0) + n
    for (seq, provider, reward, slots), n in open_slots.items():
        fee = fees[provider].reward_fee_cents(reward, slots)
        for target, key in ((by_sequence, str(seq)), (by_provider, provider)):
            _add(target, key, committed_rewards=n * reward, committed_fees=n * fee)


def _line(key: str, cents: list[int], label: str | None = None,
          currency: str = "USD") -> CostLine:
    money = pricing.cents_to_dollars
    parts = {name: money(value) for name, value in zip(FIELDS, cents, strict=True)}
    return CostLine(key=key, name=key if label is None else label, spent=money(sum(cents[:3])),
                    committed=money(sum(cents[3:])), currency=currency, **parts)


def _sequence_names(session: Session, keys: list[str]) -> dict[str, str]:
    """"subject/name" of each sequence id (as a string) of ``keys``."""
    rows = session.execute(select(Sequence.id, Subject.name, Sequence.name)
                           .join(Subject, Subject.id == Sequence.subject_id)
                           .where(Sequence.id.in_([int(k) for k in keys])))
    return {str(seq): f"{subject}/{name}" for seq, subject, name in rows}


def keep_deleted(session: Session, sequence_id: int, name: str) -> int:
    """Copy the ledger of sequence ``sequence_id`` (about to be deleted with its work) into
    crowd_deleted_costs, per worker, kind and state; the number of payment rows kept."""
    rows = session.execute(
        select(CrowdPayment.worker_id, CrowdPayment.provider, CrowdPayment.kind,
               CrowdPayment.state, func.sum(CrowdPayment.amount_cents),
               func.sum(CrowdPayment.fee_cents), func.count())
        .join(Assignment, Assignment.id == CrowdPayment.assignment_id)
        .join(Task, Task.id == Assignment.task_id).where(Task.sequence_id == sequence_id)
        .group_by(CrowdPayment.worker_id, CrowdPayment.provider, CrowdPayment.kind,
                  CrowdPayment.state)).all()
    totals.forget_sequence(session, sequence_id)
    session.add_all(CrowdDeletedCost(sequence_id=sequence_id, sequence_name=name,
                                     worker_id=worker, provider=provider, kind=kind,
                                     state=state, amount_cents=int(amount), fee_cents=int(fee),
                                     payments=n)
                    for worker, provider, kind, state, amount, fee, n in rows)
    session.flush()
    return sum(int(n) for *_, n in rows)


def _deleted(session: Session, by_sequence: _Totals) -> dict[str, str]:
    """The ledger kept for deleted sequences, added under "deleted:<id>" keys (the workers'
    totals never lost it); their names."""
    names: dict[str, str] = {}
    for row in session.scalars(select(CrowdDeletedCost)):
        key = f"deleted:{row.sequence_id}"
        names[key] = f"{row.sequence_name} (deleted)"
        _add(by_sequence, key,
             **_payment_parts(row.kind, row.state, row.amount_cents, row.fee_cents))
    return names


def _order(key: str) -> tuple[int, int]:
    """Sequences by id, deleted ones after the others."""
    deleted = key.startswith("deleted:")
    return (int(deleted), int(key.removeprefix("deleted:")))


def costs(session: Session) -> CostsRead:
    """Spend and commitments for the project, per sequence (keyed by id, named subject/name),
    per worker and per provider (in its currency)."""
    scopes: dict[str, _Totals] = {"sequence": {}, "worker": {}, "provider": {}}
    by_sequence = scopes["sequence"]
    _payments(session, scopes)
    _held(session, scopes)
    deleted_names = _deleted(session, by_sequence)
    total = [sum(column) for column in zip(*by_sequence.values(), strict=True)] \
        or [0] * len(FIELDS)
    names = _sequence_names(session, [k for k in by_sequence if k not in deleted_names])
    names.update(deleted_names)
    fees = _Fees()
    currencies = {fees[name].currency for name in scopes["provider"]} or {"USD"}
    return CostsRead(
        total=_line("project", total,
                    currency=currencies.pop() if len(currencies) == 1 else "mixed"),
        by_sequence=[_line(k, by_sequence[k], names.get(k, f"sequence {k}"))
                     for k in sorted(by_sequence, key=_order)],
        by_worker=[_line(k, v) for k, v in sorted(scopes["worker"].items())],
        by_provider=[_line(k, v, currency=fees[k].currency)
                     for k, v in sorted(scopes["provider"].items())])
