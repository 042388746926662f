"""Crowd runs: which tasks are due, what they cost, publishing them, and paying bonuses.

``publish`` works inside the caller's unit of work (the API request), one provider batch for
all due tasks. ``publish_each`` is the CLI's run: one unit of work per provider call (per task
on MTurk, whose every HIT is a call of its own; one batch where the provider makes one), so an
interrupted run keeps every unit it recorded and a re-run only has the rest to do.
``pay_bonus`` commits its ledger row before it pays and again after, so a bonus is never paid
twice (decisions.py says how).
"""

from __future__ import annotations

from sqlalchemy import Select, func, select
from sqlalchemy.orm import Session

from backend.annotation.models import Task
from backend.config import get_settings
from backend.crowd import actions, adaptive, decisions, pricing
from backend.crowd.models import CrowdHit
from backend.crowd.provider import CrowdProvider, Requirements
from backend.crowd.providers import fees_of, get_provider, provider_of
from backend.crowd.publish import check_assignments, publish_tasks, requirements, unit_spec
from backend.crowd.schemas import CostRead, PaymentRead, PublishOptions, PublishResult
from backend.db import session_scope
from backend.errors import DexlabelError

_COUNTERS = {"created": "created", "recovered": "recovered", "existing": "already_published"}


def due_task_ids(session: Session, round_: int, sequence_id: int | None = None,
                 kind: str | None = None) -> list[int]:
    """Tasks with no HIT yet in ``round_`` (optionally of one sequence, of one kind), by id."""
    return list(session.scalars(_due(round_, sequence_id, kind).order_by(Task.id)))


def _due(round_: int, sequence_id: int | None, kind: str | None) -> Select[int]:
    published = select(CrowdHit.task_id).where(
        CrowdHit.round == round_, CrowdHit.hit_id.is_not(None))
    stmt = select(Task.id).where(Task.id.not_in(published))
    if sequence_id is not None:
        stmt = stmt.where(Task.sequence_id == sequence_id)
    if kind is not None:
        stmt = stmt.where(Task.kind == kind)
    return stmt


def _provider(crowd: CrowdProvider | None, options: PublishOptions) -> CrowdProvider:
    """The provider a publish goes to: the one given, else the options' (else the setting's)."""
    return provider_of(crowd) if crowd is not None else get_provider(options.provider)


def cost_read(hits: int, options: PublishOptions, provider: str = "mturk") -> CostRead:
    """The cost of ``hits`` units of ``options`` in the fees and currency of ``provider``."""
    fees = fees_of(provider)
    reward = pricing.dollars_to_cents(options.reward)
    places = options.max_assignments
    fee = fees.reward_fee_cents(reward, places)
    rewards, fees_total = hits * places * reward, hits * places * fee
    money = pricing.cents_to_dollars
    return CostRead(provider=fees.provider, currency=fees.currency, hits=hits,
                    assignments_per_hit=places, reward=money(reward),
                    fee_per_assignment=money(fee), rewards=money(rewards),
                    fees=money(fees_total), total=money(rewards + fees_total))


def chosen_tasks(session: Session, options: PublishOptions, sequence_id: int | None,
                 kind: str | None = None) -> dict[int, str | None]:
    """The due tasks a publish with ``options`` sends under its policy (backend.crowd.adaptive),
    by id, each with why it is published (None: every view at once)."""
    due = due_task_ids(session, options.round, sequence_id, kind)
    return adaptive.select_due(session, due, adaptive.policy_of(options))


def record_plans(session: Session, options: PublishOptions, sequence_id: int | None,
                 task_ids: list[int]) -> None:
    """Keep the policy of the sequences a publish touches: every sequence published under
    the adaptive policy, and those that had one and are now published with every view."""
    policy = adaptive.policy_of(options)
    sequences = {sequence_id} if sequence_id is not None else set(session.scalars(
        select(Task.sequence_id).where(Task.id.in_(task_ids))))
    for seq in sorted(sequences):
        if policy.name == adaptive.ADAPTIVE or adaptive.plan_of(session, seq) is not None:
            adaptive.record_plan(session, seq, policy, options)


def plan(session: Session, options: PublishOptions, sequence_id: int | None,
         kind: str | None = None, provider: str | None = None) -> PublishResult:
    """What a publish would do: the unit count and cost, nothing sent."""
    return _planned(session, options, sequence_id, kind, provider)[0]


def _planned(session: Session, options: PublishOptions, sequence_id: int | None,
             kind: str | None, provider: str | None
             ) -> tuple[PublishResult, dict[int, str | None]]:
    """:func:`plan`, and the tasks it counted with their reasons (:func:`chosen_tasks`)."""
    name = provider or options.provider or get_settings().crowd_provider
    check_assignments(options.max_assignments, options.allow_large_hits, fees_of(name))
    due = chosen_tasks(session, options, sequence_id, kind)
    check_due(session, _due(options.round, sequence_id, kind), options, name)
    return PublishResult(cost=cost_read(len(due), options, name)), due


def check_due(session: Session, due: Select[int], options: PublishOptions,
              name: str) -> None:
    """The provider's checks before publishing (its reward floor, its requirements) on one
    unit of each kind of task ``due`` selects, so a dry run refuses what the publish would."""
    firsts = session.execute(select(Task.kind, func.min(Task.id)).where(Task.id.in_(due))
                             .group_by(Task.kind)).all()
    if not firsts:
        return
    reqs = Requirements(locales=tuple(options.locales), assignee=options.assignee)
    get_provider(name).check_publish(
        [unit_spec(session, session.get_one(Task, task_id), options, reqs)
         for _, task_id in firsts])


def publish(
    session: Session, crowd: CrowdProvider | None, options: PublishOptions,
    sequence_id: int | None,
) -> PublishResult:
    """Publish every due task in this unit of work, in one provider batch (safe to re-run
    after any failure). ``crowd``: the provider (None: ``options.provider``, else the
    setting's).

    Rows are written only after the last provider call (no autoflush in between), so no
    write transaction is held open across HTTP calls.
    """
    provider = _provider(crowd, options)
    result, reasons = _planned(session, options, sequence_id, None, provider.name)
    with session.no_autoflush:
        if reasons:
            reqs = requirements(session, provider, options)
            tasks = [session.get_one(Task, task_id) for task_id in reasons]
            for unit_id, outcome in publish_tasks(session, provider, tasks, options, reqs,
                                                  reasons):
                _count(result, unit_id, outcome)
        record_plans(session, options, sequence_id, list(reasons))
    session.flush()
    return result


def publish_each(
    crowd: CrowdProvider | None, options: PublishOptions, sequence_id: int | None,
    kind: str | None = None,
) -> PublishResult:
    """Publish every due task (of ``kind``: "hand", "object"; None: all), one unit of work
    (and commit) per provider call: per task where the provider makes a call per unit
    (``publish_chunk``), else all in one."""
    provider = _provider(crowd, options)
    with session_scope() as session:
        result, reasons = _planned(session, options, sequence_id, kind, provider.name)
        with session.no_autoflush:
            reqs = requirements(session, provider, options) if reasons else None
        record_plans(session, options, sequence_id, list(reasons))
    _publish_in_chunks(provider, options, reqs, reasons, result)
    return result


def publish_needed(crowd: CrowdProvider | None, sequence_id: int,
                   reasons: dict[int, str]) -> PublishResult:
    """Publish the views a solve found needed (backend.crowd.adaptive.needed_views) with the
    options of the sequence's plan and their reasons, one unit of work per provider call as
    :func:`publish_each`."""
    with session_scope() as session:
        options = adaptive.plan_options(session, sequence_id)
        if options is None:
            raise DexlabelError(f"sequence {sequence_id} is not published adaptively")
        provider = _provider(crowd, options)
        with session.no_autoflush:
            reqs = requirements(session, provider, options) if reasons else None
    result = PublishResult(cost=cost_read(len(reasons), options, provider.name))
    _publish_in_chunks(provider, options, reqs, dict(reasons), result)
    return result


def _publish_in_chunks(provider: CrowdProvider, options: PublishOptions,
                       reqs: Requirements | None, reasons: dict[int, str | None],
                       result: PublishResult) -> None:
    """One unit of work (and commit) per provider call: per task where the provider makes a
    call per unit (``publish_chunk``), else all in one."""
    task_ids = list(reasons)
    chunk = int(getattr(provider, "publish_chunk", 0)) or max(len(task_ids), 1)
    for start in range(0, len(task_ids), chunk):
        with session_scope() as session, session.no_autoflush:
            tasks = [session.get_one(Task, task_id)
                     for task_id in task_ids[start:start + chunk]]
            for unit_id, outcome in publish_tasks(session, provider, tasks, options, reqs,
                                                  reasons):
                _count(result, unit_id, outcome)


def pay_bonus(crowd: CrowdProvider | None, assignment_id: int, amount_cents: int, reason: str,
              key: str = "1") -> PaymentRead:
    """Pay a bonus once per (assignment, key): commit a pending row, pay, commit it done.
    ``crowd``: the provider (None: the assignment's own).

    A repeat returns the recorded payment (``already_done``); a run that died after the first
    commit is finished by the next one, which asks the provider before paying.
    """
    with session_scope() as session:
        intent = decisions.begin_bonus(session, assignment_id, amount_cents, reason, key)
    if intent.payment is not None:
        return intent.payment
    decisions.send_bonus(crowd, intent)
    with session_scope() as session:
        return decisions.finish_bonus(session, intent.token)


def _count(result: PublishResult, hit_id: str, outcome: str) -> None:
    field = _COUNTERS[outcome]
    setattr(result, field, getattr(result, field) + 1)
    result.hit_ids.append(hit_id)


def expire_sequence_hits(sequence_id: int, crowd: CrowdProvider | None = None) -> list[str]:
    """Close every open unit of the sequence's tasks with its provider (no more work is taken;
    submitted work can still be decided), one committed unit of work each; their ids.

    A provider that refuses or cannot be reached stops here with its error, so a delete that
    needs the units closed first does not go on. ``crowd``: the provider (None: each unit's
    own).
    """
    with session_scope() as session:
        open_hits = list(session.scalars(
            select(CrowdHit.hit_id).join(Task, Task.id == CrowdHit.task_id)
            .where(Task.sequence_id == sequence_id, CrowdHit.hit_id.is_not(None),
                   CrowdHit.expired_at.is_(None)).order_by(CrowdHit.id)))
    done: list[str] = []
    for hit_id in open_hits:
        assert hit_id is not None
        with session_scope() as session, session.no_autoflush:
            actions.expire_hit(session, crowd, hit_id)
        done.append(hit_id)
    return done
