"""Requester operations on assignments: read, list, approve, reject.

Only submitted work is visible to the requester (Submitted, Approved, Rejected); an assignment a
worker holds, returned or abandoned does not exist as far as the requester API is concerned.
"""

from __future__ import annotations

from datetime import timedelta
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import selectinload

from backend.market import ledger, lifecycle
from backend.market.context import Call
from backend.market.errors import (
    ASSIGNMENT_DOES_NOT_EXIST,
    INVALID_ASSIGNMENT_STATE,
    RequestError,
    invalid,
    not_found,
)
from backend.market.hits import get_hit_or_raise
from backend.market.lifecycle import HitState
from backend.market.models import Hit, MarketAssignment
from backend.market.pagination import page

VISIBLE = ("Submitted", "Approved", "Rejected")
MAX_FEEDBACK = 1024
# MTurk lets a rejection be overridden for work submitted within the last 30 days.
OVERRIDE_WINDOW = timedelta(days=30)


def get_assignment_or_raise(call: Call, assignment_id: str) -> tuple[MarketAssignment, HitState]:
    """The requester's submitted assignment (and its HIT's state), with due changes applied."""
    stmt = (select(MarketAssignment).join(MarketAssignment.hit)
            .where(MarketAssignment.assignment_id == assignment_id,
                   Hit.requester == call.requester_id)
            .options(selectinload(MarketAssignment.hit).selectinload(Hit.assignments),
                     selectinload(MarketAssignment.hit).selectinload(Hit.hit_type)))
    assignment = call.session.scalars(stmt).one_or_none()
    if assignment is None:
        raise not_found("Assignment", assignment_id, ASSIGNMENT_DOES_NOT_EXIST)
    state = lifecycle.refresh_hit(call.session, assignment.hit, call.now)
    if assignment.status not in VISIBLE:
        raise not_found("Assignment", assignment_id, ASSIGNMENT_DOES_NOT_EXIST)
    return assignment, state


def list_for_hit(call: Call, params: dict[str, Any]) -> tuple[list[MarketAssignment], str | None]:
    """Submitted, approved and rejected assignments of a HIT (or those of the asked statuses)."""
    hit, _ = get_hit_or_raise(call, params["HITId"])
    statuses = params.get("AssignmentStatuses") or list(VISIBLE)
    stmt = (select(MarketAssignment).where(MarketAssignment.hit_pk == hit.id,
                                     MarketAssignment.status.in_(statuses))
            .options(selectinload(MarketAssignment.hit)))
    return page(call.session, stmt, MarketAssignment.id, "ListAssignmentsForHIT", params)


def _feedback(text: str | None, required: bool) -> str | None:
    if required and not (text or "").strip():
        raise invalid("RequesterFeedback is required when rejecting an assignment")
    if text is not None and len(text) > MAX_FEEDBACK:
        raise invalid(f"RequesterFeedback may be at most {MAX_FEEDBACK} characters")
    return text


def _wrong_state(assignment: MarketAssignment, operation: str, allowed: str) -> RequestError:
    return RequestError(
        f"Assignment {assignment.assignment_id} is {assignment.status}; {operation} can be "
        f"called with a status of: {allowed}.", INVALID_ASSIGNMENT_STATE)


def approve(
    call: Call, assignment_id: str, feedback: str | None, override_rejection: bool
) -> MarketAssignment:
    """Approve submitted work (paid from the HIT's hold), or with ``override_rejection``
    rejected work (paid from the available balance)."""
    assignment, state = get_assignment_or_raise(call, assignment_id)
    feedback = _feedback(feedback, required=False)
    if assignment.status == "Submitted":
        ledger.pay_from_hold(call.session, assignment, call.now)
    elif assignment.status == "Rejected" and override_rejection:
        if state.status == "Disposed":
            raise RequestError(f"HIT {assignment.hit.hit_id} has been deleted; its rejected "
                               "assignments can no longer be approved.", INVALID_ASSIGNMENT_STATE)
        if assignment.submit_time is None or assignment.submit_time + OVERRIDE_WINDOW < call.now:
            raise RequestError("A rejection can be overridden only for work submitted within "
                               "the last 30 days.", INVALID_ASSIGNMENT_STATE)
        ledger.pay_directly(call.session, call.requester, assignment, call.now)
    else:
        allowed = "Submitted" + (" (or Rejected, with OverrideRejection)"
                                 if assignment.status == "Rejected" else "")
        raise _wrong_state(assignment, "ApproveAssignment", allowed)
    assignment.status = "Approved"
    assignment.approval_time = call.now
    assignment.rejection_time = None
    assignment.requester_feedback = feedback
    lifecycle.refresh_hit(call.session, assignment.hit, call.now)
    return assignment


def reject(call: Call, assignment_id: str, feedback: str | None) -> MarketAssignment:
    """Reject submitted work; its reward and fee return to the available balance."""
    assignment, _ = get_assignment_or_raise(call, assignment_id)
    feedback = _feedback(feedback, required=True)
    if assignment.status != "Submitted":
        raise _wrong_state(assignment, "RejectAssignment", "Submitted")
    assignment.status = "Rejected"
    assignment.rejection_time = call.now
    assignment.requester_feedback = feedback
    lifecycle.refresh_hit(call.session, assignment.hit, call.now)
    return assignment
