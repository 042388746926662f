"""Crowd runs: which tasks are due, what they cost, publishing them, and paying bonuses.

``publish`` works inside the caller's unit of work (the API request). ``publish_each`` is the
CLI's run: one unit of work per task, so an interrupted run keeps every HIT it recorded and a
re-run only has the rest to do. ``pay_bonus`` commits its ledger row before it pays and again
after, so a bonus is never paid twice (decisions.py says how).
"""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.models import Task
from backend.config import get_settings
from backend.crowd import actions, decisions, pricing
from backend.crowd.client import MTurkClient, make_client
from backend.crowd.models import CrowdHit
from backend.crowd.publish import check_assignments, publish_task, requirements
from backend.crowd.schemas import CostRead, PaymentRead, PublishOptions, PublishResult
from backend.db import session_scope

_COUNTERS = {"created": "created", "recovered": "recovered", "existing": "already_published"}


def due_task_ids(session: Session, round_: int, sequence_id: int | None = None,
                 kind: str | None = None) -> list[int]:
    """Tasks with no HIT yet in ``round_`` (optionally of one sequence, of one kind), by id."""
    published = select(CrowdHit.task_id).where(
        CrowdHit.round == round_, CrowdHit.hit_id.is_not(None))
    stmt = select(Task.id).where(Task.id.not_in(published)).order_by(Task.id)
    if sequence_id is not None:
        stmt = stmt.where(Task.sequence_id == sequence_id)
    if kind is not None:
        stmt = stmt.where(Task.kind == kind)
    return list(session.scalars(stmt))


def cost_read(hits: int, options: PublishOptions) -> CostRead:
    cost = pricing.estimate(hits, options.max_assignments, pricing.dollars_to_cents(options.reward))
    money = pricing.cents_to_dollars
    return CostRead(hits=hits, assignments_per_hit=options.max_assignments,
                    reward=money(cost.reward_cents),
                    fee_per_assignment=money(cost.fee_cents_per_assignment),
                    rewards=money(cost.rewards_cents), fees=money(cost.fees_cents),
                    total=money(cost.total_cents))


def plan(session: Session, options: PublishOptions, sequence_id: int | None,
         kind: str | None = None) -> PublishResult:
    """What a publish would do: the HIT count and cost, nothing sent."""
    check_assignments(options.max_assignments, options.allow_large_hits)
    due = due_task_ids(session, options.round, sequence_id, kind)
    return PublishResult(cost=cost_read(len(due), options))


def publish(
    session: Session, client: MTurkClient, options: PublishOptions, sequence_id: int | None,
) -> PublishResult:
    """Publish every due task in this unit of work (safe to re-run after any failure).

    Rows are written only after the last marketplace call (no autoflush in between), so no
    write transaction is held open across HTTP calls.
    """
    result = plan(session, options, sequence_id)
    with session.no_autoflush:
        task_ids = due_task_ids(session, options.round, sequence_id)
        reqs = requirements(session, client, options) if task_ids else []
        for task_id in task_ids:
            task = session.get_one(Task, task_id)
            _count(result, *publish_task(session, client, task, options, reqs))
    session.flush()
    return result


def publish_each(
    client: MTurkClient, options: PublishOptions, sequence_id: int | None,
    kind: str | None = None,
) -> PublishResult:
    """Publish every due task (of ``kind``: "hand", "object"; None: all), one unit of work
    (and commit) per HIT."""
    with session_scope() as session:
        result = plan(session, options, sequence_id, kind)
        with session.no_autoflush:
            task_ids = due_task_ids(session, options.round, sequence_id, kind)
            reqs = requirements(session, client, options) if task_ids else []
    for task_id in task_ids:
        with session_scope() as session, session.no_autoflush:
            task = session.get_one(Task, task_id)
            _count(result, *publish_task(session, client, task, options, reqs))
    return result


def pay_bonus(client: MTurkClient, assignment_id: int, amount_cents: int, reason: str,
              key: str = "1") -> PaymentRead:
    """Pay a bonus once per (assignment, key): commit a pending row, pay, commit it done.

    A repeat returns the recorded payment (``already_done``); a run that died after the first
    commit is finished by the next one, which checks the marketplace before paying.
    """
    with session_scope() as session:
        intent = decisions.begin_bonus(session, assignment_id, amount_cents, reason, key)
    if intent.payment is not None:
        return intent.payment
    decisions.send_bonus(client, intent)
    with session_scope() as session:
        return decisions.finish_bonus(session, intent.token)


def _count(result: PublishResult, hit_id: str, outcome: str) -> None:
    field = _COUNTERS[outcome]
    setattr(result, field, getattr(result, field) + 1)
    result.hit_ids.append(hit_id)


def expire_sequence_hits(sequence_id: int, client: MTurkClient | None = None) -> list[str]:
    """Expire every open HIT of the sequence's tasks on the marketplace (no more work is taken;
    submitted work can still be decided), one committed unit each; their ids.

    A marketplace that refuses or cannot be reached stops here with its error, so a delete
    that needs the HITs closed first does not go on. The client is made only when there is a
    HIT to expire.
    """
    with session_scope() as session:
        open_hits = list(session.scalars(
            select(CrowdHit.hit_id).join(Task, Task.id == CrowdHit.task_id)
            .where(Task.sequence_id == sequence_id, CrowdHit.hit_id.is_not(None),
                   CrowdHit.expired_at.is_(None)).order_by(CrowdHit.id)))
    done: list[str] = []
    if open_hits and client is None:
        client = make_client(get_settings())
    for hit_id in open_hits:
        assert hit_id is not None
        with session_scope() as session, session.no_autoflush:
            actions.expire_hit(session, client, hit_id)
        done.append(hit_id)
    return done
