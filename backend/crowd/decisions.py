"""Review of submitted work: approve, reject and bonus, each recorded once in the ledger.

Approvals and rejections are one per assignment (a second one is a clear Conflict); the
provider call comes before our writes, since a write transaction held across an HTTP call
would lock the embedded SQLite database the built-in marketplace shares.

A bonus is keyed by (assignment, key) and paid in three steps, each its own unit of work (see
``flows.pay_bonus``): ``begin_bonus`` commits a pending ledger row, ``send_bonus`` has the
provider pay it under the deterministic key, ``finish_bonus`` marks the row done. A run that
lost the reply or its last commit leaves the row pending, and the next run asks the provider
whether it shows the bonus paid (``bonus_paid``) before paying, so even after the provider
forgot the key (MTurk: 24 h) nothing is paid twice.

Each call goes to the provider of the assignment's row unless the caller hands one in.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment
from backend.annotation.service import get_assignment_or_raise
from backend.config import get_settings
from backend.crowd import pricing, totals
from backend.crowd.models import CrowdHit, CrowdPayment
from backend.crowd.provider import BonusOrder, CrowdProvider
from backend.crowd.providers import fees_of, get_provider, provider_of
from backend.crowd.schemas import PaymentRead
from backend.crowd.sync import LEDGER_STATUS, verified_submission
from backend.errors import Conflict, DexlabelError, NotFound

_DONE = {"approval": "approved", "rejection": "rejected"}


class MissingFeedback(DexlabelError, status_code=422, code="validation_error"):
    pass


def _payment_read(row: CrowdPayment, already_done: bool = False) -> PaymentRead:
    return PaymentRead(kind=row.kind, assignment_id=row.assignment_id, worker_id=row.worker_id,
                       amount=pricing.cents_to_dollars(row.amount_cents),
                       fee=pricing.cents_to_dollars(row.fee_cents), already_done=already_done)


def _decision(session: Session, assignment: Assignment) -> CrowdPayment | None:
    return session.scalar(select(CrowdPayment).where(
        CrowdPayment.assignment_id == assignment.id,
        CrowdPayment.kind.in_(("approval", "rejection"))))


def crowd_of(crowd: CrowdProvider | None, assignment: Assignment) -> CrowdProvider:
    """The provider to ask about ``assignment``: the one given, else the assignment's own."""
    return provider_of(crowd) if crowd is not None else get_provider(assignment.provider)


def _market_status(crowd: CrowdProvider | None, assignment: Assignment) -> str:
    """The provider's status of the assignment, as the ledger spells it ("Rejected")."""
    record = crowd_of(crowd, assignment).submission(assignment.external_id)
    if record is None:
        raise NotFound(f"the crowd provider has no submission {assignment.external_id}")
    return LEDGER_STATUS[record.status]


# The most a marketplace takes as a decision's feedback (MTurk's RequesterFeedback: 1024).
FEEDBACK_LIMIT = 1024
_SENTENCE_END = re.compile(r"(?<=[.!?:])\s+(?=[A-Z(])")


def fit_feedback(text: str, limit: int = FEEDBACK_LIMIT) -> str:
    """``text`` cut to at most ``limit`` characters at a sentence's end (the first sentences
    are the ones that say what to fix), with " ..." where sentences were left out; a first
    sentence longer than the limit is cut at a word."""
    if len(text) <= limit:
        return text
    kept = ""
    for sentence in _SENTENCE_END.split(text):
        joined = f"{kept} {sentence}" if kept else sentence
        if len(joined) + 4 > limit:
            break
        kept = joined
    if not kept:
        kept = text[: limit - 4].rsplit(" ", 1)[0]
    return f"{kept} ..."


def _decide(session: Session, crowd: CrowdProvider | None, assignment_id: int, kind: str,
            feedback: str | None, category: str | None = None) -> PaymentRead:
    assignment = get_assignment_or_raise(session, assignment_id)
    earlier = _decision(session, assignment)
    if earlier is not None:
        raise Conflict(f"assignment {assignment_id} is already {_DONE[earlier.kind]}",
                       state=_DONE[earlier.kind])
    submission = verified_submission(session, assignment)
    provider = crowd_of(crowd, assignment)
    # Decided with the provider by an earlier run whose commit was lost: not an error there.
    if kind == "approval":
        provider.approve(assignment.external_id, feedback)
    else:
        provider.reject(assignment.external_id, feedback or "", category)
    hit = session.scalar(select(CrowdHit).where(CrowdHit.hit_id == submission.hit_id))
    amount = hit.reward_cents if hit is not None and kind == "approval" else 0
    fee = provider.fees().reward_fee_cents(amount, hit.max_assignments) \
        if amount and hit else 0
    row = CrowdPayment(kind=kind, assignment_id=assignment.id, worker_id=assignment.worker_id,
                       request_token=f"{kind}-{assignment.id}", amount_cents=amount,
                       fee_cents=fee, feedback=feedback, provider=provider.name)
    session.add(row)
    assignment.status = _DONE[kind]
    submission.market_status = LEDGER_STATUS["approved" if kind == "approval" else "rejected"]
    totals.record(session, row)
    return _payment_read(row)


def approve(session: Session, crowd: CrowdProvider | None, assignment_id: int,
            feedback: str | None = None) -> PaymentRead:
    return _decide(session, crowd, assignment_id, "approval", feedback)


def reject(session: Session, crowd: CrowdProvider | None, assignment_id: int, feedback: str,
           category: str | None = None) -> PaymentRead:
    if not feedback.strip():
        raise MissingFeedback("a rejection needs feedback that tells the worker why",
                              field="feedback")
    return _decide(session, crowd, assignment_id, "rejection", feedback, category)


def bonus_token(assignment_id: int, key: str) -> str:
    """Deterministic per (assignment, key) and deployment; at most 64 characters."""
    seed = f"{get_settings().signing_key}|bonus|{assignment_id}|{key}".encode()
    return f"dxbonus-{assignment_id}-{hashlib.sha256(seed).hexdigest()[:32]}"


@dataclass(frozen=True)
class BonusIntent:
    """A bonus about to be paid, as recorded (pending) in the ledger before the provider call.

    ``state``: "new" (the row was just written), "pending" (an earlier run wrote it and lost the
    provider's reply or its own commit) or "done" (``payment`` holds the recorded one).
    ``same_paid``: other done bonuses of this assignment with the same amount and reason,
    so a pending one is matched against the provider's list without counting them.
    """

    token: str
    state: str
    market_assignment_id: str
    worker_id: str
    amount_cents: int
    reason: str
    same_paid: int = 0
    payment: PaymentRead | None = None
    provider: str = "mturk"
    unit_id: str = ""

    def order(self) -> BonusOrder:
        return BonusOrder(key=self.token, assignment_id=self.market_assignment_id,
                          unit_id=self.unit_id, worker_id=self.worker_id,
                          amount_cents=self.amount_cents, reason=self.reason,
                          same_paid=self.same_paid)


def begin_bonus(session: Session, assignment_id: int, amount_cents: int, reason: str,
                key: str = "1") -> BonusIntent:
    """Find the bonus (assignment, key) in the ledger, or add it as pending.

    The caller commits the pending row before calling ``send_bonus``: the row then outlives the
    marketplace's 24-hour token memory, whatever happens to the call.
    """
    assignment = get_assignment_or_raise(session, assignment_id)
    submission = verified_submission(session, assignment)
    token = bonus_token(assignment.id, key)
    row = session.scalar(select(CrowdPayment).where(CrowdPayment.request_token == token))
    if row is not None and row.amount_cents != amount_cents:
        raise Conflict(f"bonus {key!r} of assignment {assignment_id} was already "
                       f"{'paid' if row.state == 'done' else 'started'} with "
                       f"${pricing.cents_to_dollars(row.amount_cents)}; use another key")
    intent: dict[str, Any] = {"token": token, "market_assignment_id": assignment.external_id,
                              "worker_id": submission.worker_id, "amount_cents": amount_cents,
                              "reason": reason, "provider": assignment.provider,
                              "unit_id": submission.hit_id}
    if row is not None and row.state == "done":
        return BonusIntent(state="done", payment=_payment_read(row, already_done=True), **intent)
    if row is not None:
        # Checked and resent with the reason it was started with: the provider lists it so.
        intent["reason"] = row.feedback or reason
        return BonusIntent(state="pending", same_paid=_same_paid(session, row), **intent)
    row = CrowdPayment(kind="bonus", assignment_id=assignment.id,
                       worker_id=submission.worker_id, request_token=token,
                       amount_cents=amount_cents,
                       fee_cents=fees_of(assignment.provider).bonus_fee_cents(amount_cents),
                       feedback=reason, state="pending", provider=assignment.provider)
    session.add(row)
    try:
        totals.record(session, row)
    except IntegrityError as exc:
        raise Conflict(f"bonus {key!r} of assignment {assignment_id} is being paid by another "
                       "request; try again", state="pending") from exc
    return BonusIntent(state="new", **intent)


def _same_paid(session: Session, row: CrowdPayment) -> int:
    count = session.scalar(select(func.count()).select_from(CrowdPayment).where(
        CrowdPayment.assignment_id == row.assignment_id, CrowdPayment.kind == "bonus",
        CrowdPayment.state == "done", CrowdPayment.amount_cents == row.amount_cents,
        CrowdPayment.feedback == row.feedback, CrowdPayment.id != row.id))
    return int(count or 0)


def send_bonus(crowd: CrowdProvider | None, intent: BonusIntent) -> None:
    """Have the provider pay the bonus unless an earlier run already did (no DB access).
    ``crowd``: the provider (None: the assignment's own)."""
    if intent.state == "done":
        return
    provider = provider_of(crowd) if crowd is not None else get_provider(intent.provider)
    order = intent.order()
    if intent.state == "pending" and provider.bonus_paid(order):
        return
    provider.pay_bonus(order)


def finish_bonus(session: Session, token: str) -> PaymentRead:
    """Mark the pending bonus ``token`` paid."""
    row = session.scalar(select(CrowdPayment).where(CrowdPayment.request_token == token))
    if row is None:
        raise NotFound(f"no bonus with token {token} in the ledger")
    old_state, row.state = row.state, "done"
    session.flush()
    totals.moved(session, row, old_state)
    return _payment_read(row)
