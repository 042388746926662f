"""The cost of a labelled 3D frame: per sequence and target, the human work (edit actions and
active working seconds the annotation page counted) and the money the crowd ledger spent on
it, divided by the frames the current solve labelled for that target and did not flag.

Counted per target over every assignment of its tasks (one task per view), rejected and
unfinished work included: that work was done and the frames cost it all the same. Money is
the ledger's spend as the cost report counts it (backend.crowd.costs): approved rewards and
paid bonuses, each with its fee; a rejection costs nothing and a pending bonus is not spent
yet. So a sequence's money adds up to its "spent" line of the cost report.

A labelled frame: for the hand, the solve has its joints there and no flag; for object ``i``,
its pose there carries no flag (backend.solve.results: hand_trust, object_trust).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session, selectinload

from backend.annotation.models import Assignment, Task
from backend.captures.models import Sequence
from backend.crowd.models import CrowdPayment
from backend.crowd.providers import fees_of
from backend.progress.schemas import SequenceFrameCost, TargetFrameCost
from backend.solve.results import decode_result, hand_trust, object_trust
from backend.solve.service import current_run
from backend.storage import get_storage

# Counted as spent (backend.crowd.costs): an approval's reward, a paid bonus; each with its fee.
_SPENT = (CrowdPayment.kind == "approval") | (
    (CrowdPayment.kind == "bonus") & (CrowdPayment.state == "done"))


@dataclass
class _Work:
    """What a target's tasks took: views, assignments, actions, seconds, cents per currency."""

    kind: str
    views: int = 0
    assignments: int = 0
    actions: int = 0
    seconds: float = 0.0
    cents: dict[str, int] = field(default_factory=dict)


def _money(cents: float) -> str:
    return f"{cents / 100:.2f}"


def _per_frame_money(cents: int, frames: int) -> str | None:
    # Four decimals: a frame of a long clip costs a fraction of a cent.
    return f"{cents / frames / 100:.4f}" if frames else None


def _line(key: str, work: _Work, frames: int, labelled: int, label: str) -> TargetFrameCost:
    cents = sum(work.cents.values())
    currencies = sorted(work.cents) or ["USD"]
    return TargetFrameCost(
        target_key=key, label=label, kind=work.kind, views=work.views, assignments=work.assignments,
        frames=frames, frames_labelled=labelled, actions=work.actions,
        seconds=round(work.seconds, 1), money=_money(cents), money_cents=cents,
        currency=currencies[0] if len(currencies) == 1 else "mixed",
        actions_per_frame=round(work.actions / labelled, 2) if labelled else None,
        seconds_per_frame=round(work.seconds / labelled, 2) if labelled else None,
        money_per_frame=_per_frame_money(cents, labelled))


def _work_of(session: Session, sequence_id: int) -> dict[str, _Work]:
    """Per target key of the sequence: its tasks, their work and the ledger's spend on them."""
    out: dict[str, _Work] = {}
    for key, kind, views in session.execute(
            select(Task.target_key, Task.kind, func.count())
            .where(Task.sequence_id == sequence_id).group_by(Task.target_key, Task.kind)):
        out[key] = _Work(kind=kind, views=int(views))
    for key, n, actions, seconds in session.execute(
            select(Task.target_key, func.count(), func.sum(Assignment.edit_count),
                   func.sum(Assignment.working_time_s))
            .join(Task, Task.id == Assignment.task_id)
            .where(Task.sequence_id == sequence_id).group_by(Task.target_key)):
        work = out[key]
        work.assignments, work.actions = int(n), int(actions or 0)
        work.seconds = float(seconds or 0.0)
    currency: dict[str, str] = {}
    for key, provider, amount, fee in session.execute(
            select(Task.target_key, CrowdPayment.provider, func.sum(CrowdPayment.amount_cents),
                   func.sum(CrowdPayment.fee_cents))
            .join(Assignment, Assignment.id == CrowdPayment.assignment_id)
            .join(Task, Task.id == Assignment.task_id)
            .where(Task.sequence_id == sequence_id, _SPENT)
            .group_by(Task.target_key, CrowdPayment.provider)):
        if provider not in currency:
            currency[provider] = fees_of(provider).currency
        cents = out[key].cents
        cents[currency[provider]] = cents.get(currency[provider], 0) + int(amount) + int(fee)
    return out


def labelled_masks(arrays: dict[str, np.ndarray], target_keys: list[str]) -> dict[str,
                                                                                   np.ndarray]:
    """(F,) bool per target key: the frames a solve result labelled for it without a flag.
    A target the result does not hold (an object index out of range) has none."""
    frames = len(arrays["labelled"])
    hand_ok = np.isfinite(arrays["hand_joints"]).reshape(frames, -1).all(axis=1) \
        & (hand_trust(arrays)[1] == "")
    object_flags = object_trust(arrays)[1]
    out = {}
    for key in target_keys:
        kind, _, index = key.partition(":")
        if kind == "hand":
            out[key] = hand_ok
        elif index.isdigit() and int(index) < len(object_flags):
            out[key] = object_flags[int(index)] == ""
        else:
            out[key] = np.zeros(frames, dtype=bool)
    return out


def _order(key: str) -> tuple[int, int, str]:
    kind, _, index = key.partition(":")
    return (0 if kind == "hand" else 1, int(index) if index.isdigit() else 0, key)


def sequence_frame_cost(session: Session, sequence: Sequence) -> SequenceFrameCost:
    """One sequence's cost per labelled 3D frame, per target (hand first, then the objects)
    and in total. Reads the current solve's result from storage."""
    work = _work_of(session, sequence.id)
    keys = sorted(work, key=_order)
    run = current_run(session, sequence.id)
    frames = sequence.num_frames
    masks: dict[str, np.ndarray] = {k: np.zeros(frames, dtype=bool) for k in keys}
    if run is not None and run.result_key is not None:
        arrays = decode_result(get_storage().get_bytes(run.result_key))
        frames = len(arrays["labelled"])
        masks = labelled_masks(arrays, keys)
    labels = {f"hand:{h.index}": f"{h.side} hand" for h in sequence.hands}
    labels.update({f"object:{o.index}": f"object {o.index} ({o.name})" for o in sequence.objects})
    lines = [_line(k, work[k], frames, int(masks[k].sum()),
                   labels.get(k) or k.replace(":", " ")) for k in keys]
    every = np.logical_and.reduce([masks[k] for k in keys]) if keys \
        else np.zeros(frames, dtype=bool)
    whole = _Work(kind="total", views=sum(w.views for w in work.values()),
                  assignments=sum(w.assignments for w in work.values()),
                  actions=sum(w.actions for w in work.values()),
                  seconds=sum(w.seconds for w in work.values()))
    for w in work.values():
        for currency, cents in w.cents.items():
            whole.cents[currency] = whole.cents.get(currency, 0) + cents
    return SequenceFrameCost(
        sequence_id=sequence.id, name=f"{sequence.subject.name}/{sequence.name}",
        solve_run_id=None if run is None else run.id, targets=lines,
        total=_line("total", whole, frames, int(every.sum()), "all targets"))


def frame_costs(session: Session, sequence_ids: list[int]) -> list[SequenceFrameCost]:
    """:func:`sequence_frame_cost` of each existing sequence of ``sequence_ids``, in order."""
    found = {s.id: s for s in session.scalars(
        select(Sequence).where(Sequence.id.in_(sequence_ids))
        .options(selectinload(Sequence.subject), selectinload(Sequence.hands),
                 selectinload(Sequence.objects)))}
    return [sequence_frame_cost(session, found[i]) for i in sequence_ids if i in found]

