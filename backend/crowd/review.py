"""Review of submitted work: approve, reject and bonus, each recorded once in the ledger.

Approvals and rejections are one per assignment (a second one is a clear Conflict). A bonus is
keyed by (assignment, key): its UniqueRequestToken is derived from that and its ledger row is
checked first, so botocore's retries, a replayed token ("already been processed") or a re-run
never pay twice. Every marketplace call comes before our writes: a write transaction held
across an HTTP call would lock the embedded SQLite database the built-in marketplace shares.
"""

from __future__ import annotations

import hashlib

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment
from backend.annotation.service import get_assignment_or_raise
from backend.config import get_settings
from backend.crowd import pricing
from backend.crowd.client import MarketplaceError, MTurkClient, call
from backend.crowd.models import CrowdHit, CrowdPayment
from backend.crowd.schemas import PaymentRead
from backend.crowd.sync import verified_submission
from backend.errors import Conflict, DexlabelError

INVALID_ASSIGNMENT_STATE = "AWS.MechanicalTurk.InvalidAssignmentState"
_REPLAYED = "already been processed"
_DONE = {"approval": "approved", "rejection": "rejected"}
_MARKET_STATUS = {"approval": "Approved", "rejection": "Rejected"}


class MissingFeedback(DexlabelError):
    status_code = 422
    code = "validation_error"


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
    session.flush()
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
    seed = f"{get_settings().secret_key}|bonus|{assignment_id}|{key}".encode()
    return f"dxbonus-{assignment_id}-{hashlib.sha256(seed).hexdigest()[:32]}"


def bonus(session: Session, client: MTurkClient, assignment_id: int, amount_cents: int,
          reason: str, key: str = "1") -> PaymentRead:
    """Pay a bonus once per (assignment, key); a repeat returns the recorded payment."""
    assignment = get_assignment_or_raise(session, assignment_id)
    submission = verified_submission(session, assignment)
    token = bonus_token(assignment.id, key)
    row = session.scalar(select(CrowdPayment).where(CrowdPayment.request_token == token))
    if row is not None:
        if row.amount_cents != amount_cents:
            raise Conflict(f"bonus {key!r} of assignment {assignment_id} was already paid "
                           f"with ${pricing.cents_to_dollars(row.amount_cents)}; use another key")
        return _payment_read(row, already_done=True)
    try:
        call(client, "send_bonus", WorkerId=submission.worker_id,
             AssignmentId=assignment.external_id,
             BonusAmount=pricing.cents_to_dollars(amount_cents), Reason=reason,
             UniqueRequestToken=token)
    except MarketplaceError as exc:
        # The token was used by an earlier attempt whose reply or commit was lost: paid.
        if _REPLAYED not in exc.detail:
            raise
    row = CrowdPayment(kind="bonus", assignment_id=assignment.id, worker_id=submission.worker_id,
                       request_token=token, amount_cents=amount_cents,
                       fee_cents=pricing.fee_cents(amount_cents), feedback=reason)
    session.add(row)
    session.flush()
    return _payment_read(row)
