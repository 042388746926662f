"""Review of submitted work: approve, reject and bonus, each recorded once in the ledger.

Approvals and rejections are one per assignment (a second one is a clear Conflict); the
marketplace call comes before our writes, since a write transaction held across an HTTP call
would lock the embedded SQLite database the built-in marketplace shares.

A bonus is keyed by (assignment, key) and paid in three steps, each its own unit of work (see
``flows.pay_bonus``): ``begin_bonus`` commits a pending ledger row, ``send_bonus`` calls
SendBonus with the deterministic token, ``finish_bonus`` marks the row done. botocore's retries
replay the token ("already been processed"); a run that lost the reply or its last commit
leaves the row pending, and the next run asks ListBonusPayments before paying, so even after
the marketplace forgot the token (24 h) nothing is paid twice.
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
from backend.crowd.client import MarketplaceError, MTurkClient, call, paginate
from backend.crowd.models import CrowdHit, CrowdPayment
from backend.crowd.schemas import PaymentRead
from backend.crowd.sync import verified_submission
from backend.errors import Conflict, DexlabelError, NotFound

INVALID_ASSIGNMENT_STATE = "AWS.MechanicalTurk.InvalidAssignmentState"
_REPLAYED = "already been processed"
_DONE = {"approval": "approved", "rejection": "rejected"}
_MARKET_STATUS = {"approval": "Approved", "rejection": "Rejected"}


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


def _market_status(client: MTurkClient, assignment: Assignment) -> str:
    reply = call(client, "get_assignment", AssignmentId=assignment.external_id)
    return str(reply["Assignment"]["AssignmentStatus"])


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


def _decide(session: Session, client: MTurkClient, assignment_id: int, kind: str,
            feedback: str | None) -> PaymentRead:
    assignment = get_assignment_or_raise(session, assignment_id)
    earlier = _decision(session, assignment)
    if earlier is not None:
        raise Conflict(f"assignment {assignment_id} is already {_DONE[earlier.kind]}",
                       state=_DONE[earlier.kind])
    submission = verified_submission(session, assignment)
    params = {"AssignmentId": assignment.external_id}
    if feedback:
        params["RequesterFeedback"] = feedback
    operation = "approve_assignment" if kind == "approval" else "reject_assignment"
    try:
        call(client, operation, **params)
    except MarketplaceError as exc:
        # Decided on the marketplace by an earlier run whose commit was lost: record it.
        if exc.turk_code != INVALID_ASSIGNMENT_STATE or \
                _market_status(client, assignment) != _MARKET_STATUS[kind]:
            raise
    hit = session.scalar(select(CrowdHit).where(CrowdHit.hit_id == submission.hit_id))
    amount = hit.reward_cents if hit is not None and kind == "approval" else 0
    fee = pricing.fee_cents(amount, hit.max_assignments) if amount and hit else 0
    row = CrowdPayment(kind=kind, assignment_id=assignment.id, worker_id=assignment.worker_id,
                       request_token=f"{kind}-{assignment.id}", amount_cents=amount,
                       fee_cents=fee, feedback=feedback)
    session.add(row)
    assignment.status = _DONE[kind]
    submission.market_status = _MARKET_STATUS[kind]
    totals.record(session, row)
    return _payment_read(row)


def approve(session: Session, client: MTurkClient, assignment_id: int,
            feedback: str | None = None) -> PaymentRead:
    return _decide(session, client, assignment_id, "approval", feedback)


def reject(session: Session, client: MTurkClient, assignment_id: int, feedback: str) -> PaymentRead:
    if not feedback.strip():
        raise MissingFeedback("a rejection needs feedback that tells the worker why",
                              field="feedback")
    return _decide(session, client, assignment_id, "rejection", feedback)


def bonus_token(assignment_id: int, key: str) -> str:
    """Deterministic per (assignment, key) and deployment; at most 64 characters."""
    seed = f"{get_settings().signing_key}|bonus|{assignment_id}|{key}".encode()
    return f"dxbonus-{assignment_id}-{hashlib.sha256(seed).hexdigest()[:32]}"


@dataclass(frozen=True)
class BonusIntent:
    """A bonus about to be paid, as recorded (pending) in the ledger before the marketplace call.

    ``state``: "new" (the row was just written), "pending" (an earlier run wrote it and lost the
    marketplace's reply or its own commit) or "done" (``payment`` holds the recorded one).
    ``same_paid``: other done bonuses of this assignment with the same amount and reason,
    so a pending one is matched against the marketplace's list without counting them.
    """

    token: str
    state: str
    market_assignment_id: str
    worker_id: str
    amount_cents: int
    reason: str
    same_paid: int = 0
    payment: PaymentRead | None = None


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
                              "reason": reason}
    if row is not None and row.state == "done":
        return BonusIntent(state="done", payment=_payment_read(row, already_done=True), **intent)
    if row is not None:
        # Checked and resent with the reason it was started with: the marketplace lists it so.
        intent["reason"] = row.feedback or reason
        return BonusIntent(state="pending", same_paid=_same_paid(session, row), **intent)
    row = CrowdPayment(kind="bonus", assignment_id=assignment.id,
                       worker_id=submission.worker_id, request_token=token,
                       amount_cents=amount_cents, fee_cents=pricing.fee_cents(amount_cents),
                       feedback=reason, state="pending")
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


def _paid_on_market(client: MTurkClient, intent: BonusIntent) -> bool:
    """Whether the marketplace lists this bonus: more payments with its amount and reason than
    our ledger has done rows for (ListBonusPayments does not show tokens)."""
    matching = sum(
        1 for p in paginate(client, "list_bonus_payments", "BonusPayments",
                            AssignmentId=intent.market_assignment_id)
        if pricing.dollars_to_cents(p["BonusAmount"]) == intent.amount_cents
        and p["Reason"] == intent.reason)
    return matching > intent.same_paid


def send_bonus(client: MTurkClient, intent: BonusIntent) -> None:
    """Pay the bonus on the marketplace unless an earlier run already did (no DB access)."""
    if intent.state == "done":
        return
    if intent.state == "pending" and _paid_on_market(client, intent):
        return
    try:
        call(client, "send_bonus", WorkerId=intent.worker_id,
             AssignmentId=intent.market_assignment_id,
             BonusAmount=pricing.cents_to_dollars(intent.amount_cents), Reason=intent.reason,
             UniqueRequestToken=intent.token)
    except MarketplaceError as exc:
        # The token was used within 24 hours by an attempt whose reply was lost: paid.
        if _REPLAYED not in exc.detail:
            raise


def finish_bonus(session: Session, token: str) -> PaymentRead:
    """Mark the pending bonus ``token`` paid."""
    row = session.scalar(select(CrowdPayment).where(CrowdPayment.request_token == token))
    if row is None:
        raise NotFound(f"no bonus with token {token} in the ledger")
    old_state, row.state = row.state, "done"
    session.flush()
    totals.moved(session, row, old_state)
    return _payment_read(row)
