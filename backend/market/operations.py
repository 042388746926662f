"""The requester API: one handler per MTurk operation, from validated input to wire output.

Handlers only translate: the rules live in hits, assignments, payments, qualifications and
blocks. Every handler receives input that already matches the operation's input shape. The
List operations, and those that hand their whole input on and reply with nothing, are each
made by one factory (``_listing``, ``_no_output``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from backend.market import assignments, blocks, hits, payments, qualifications
from backend.market.context import Call
from backend.market.lifecycle import HitState
from backend.market.models import Hit
from backend.market.pagination import page_result
from backend.market.views import (
    assignment_view,
    bonus_view,
    hit_view,
    qualification_type_view,
    qualification_view,
)

Handler = Callable[[Call, dict[str, Any]], dict[str, Any]]
EMPTY: dict[str, Any] = {}
Row = TypeVar("Row")


def _listing(key: str, lister: Callable[[Call, dict[str, Any]], tuple[list[Row], str | None]],
             view: Callable[[Row], dict[str, Any]]) -> Handler:
    """A List operation: one page of ``lister``'s rows, each in its wire ``view``, under ``key``."""
    def handler(call: Call, params: dict[str, Any]) -> dict[str, Any]:
        found, next_token = lister(call, params)
        return page_result(key, [view(row) for row in found], next_token)
    return handler


def _no_output(action: Callable[[Call, dict[str, Any]], object]) -> Handler:
    """An operation that takes its whole input to ``action`` and replies with nothing."""
    def handler(call: Call, params: dict[str, Any]) -> dict[str, Any]:
        action(call, params)
        return EMPTY
    return handler


def _hit_row(row: tuple[Hit, HitState]) -> dict[str, Any]:
    return hit_view(*row)


def create_hit(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    hit_type = hits.find_or_create_hit_type(call, params)
    return {"HIT": hit_view(*hits.create_hit(call, hit_type, params))}


def create_hit_type(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    return {"HITTypeId": hits.find_or_create_hit_type(call, params).type_id}


def create_hit_with_hit_type(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    hit_type = hits.get_hit_type_or_raise(call, params["HITTypeId"])
    return {"HIT": hit_view(*hits.create_hit(call, hit_type, params))}


def get_hit(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    return {"HIT": hit_view(*hits.get_hit_or_raise(call, params["HITId"]))}


def update_expiration_for_hit(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    hits.update_expiration(call, params["HITId"], params["ExpireAt"])
    return EMPTY


def update_hit_review_status(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    hits.update_review_status(call, params["HITId"], bool(params.get("Revert")))
    return EMPTY


def delete_hit(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    hits.delete_hit(call, params["HITId"])
    return EMPTY


def create_additional_assignments_for_hit(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    hits.add_assignments(call, params["HITId"], params["NumberOfAdditionalAssignments"],
                         params.get("UniqueRequestToken"))
    return EMPTY


def get_assignment(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    assignment, state = assignments.get_assignment_or_raise(call, params["AssignmentId"])
    return {"Assignment": assignment_view(assignment), "HIT": hit_view(assignment.hit, state)}


def approve_assignment(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    assignments.approve(call, params["AssignmentId"], params.get("RequesterFeedback"),
                        bool(params.get("OverrideRejection")))
    return EMPTY


def reject_assignment(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    assignments.reject(call, params["AssignmentId"], params.get("RequesterFeedback"))
    return EMPTY


def get_account_balance(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    return payments.account_balance(call)


def create_qualification_type(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    return {"QualificationType": qualification_type_view(
        qualifications.create_type(call, params))}


def get_qualification_type(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    return {"QualificationType": qualification_type_view(
        qualifications.get_type_or_raise(call, params["QualificationTypeId"]))}


def create_worker_block(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    blocks.create_block(call, params["WorkerId"], params["Reason"])
    return EMPTY


def delete_worker_block(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    blocks.delete_block(call, params["WorkerId"])
    return EMPTY


def notify_workers(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    return {"NotifyWorkersFailureStatuses": blocks.notify_workers(call, params)}


# Operations that may spend available balance; they run one at a time per requester.
SPENDING = frozenset({"CreateHIT", "CreateHITWithHITType", "CreateAdditionalAssignmentsForHIT",
                      "UpdateExpirationForHIT", "ApproveAssignment", "SendBonus"})

HANDLERS: dict[str, Handler] = {
    "CreateHIT": create_hit,
    "CreateHITType": create_hit_type,
    "CreateHITWithHITType": create_hit_with_hit_type,
    "GetHIT": get_hit,
    "ListHITs": _listing("HITs", hits.list_hits, _hit_row),
    "ListReviewableHITs": _listing("HITs", hits.list_reviewable_hits, _hit_row),
    "UpdateExpirationForHIT": update_expiration_for_hit,
    "UpdateHITReviewStatus": update_hit_review_status,
    "DeleteHIT": delete_hit,
    "CreateAdditionalAssignmentsForHIT": create_additional_assignments_for_hit,
    "ListAssignmentsForHIT": _listing("Assignments", assignments.list_for_hit, assignment_view),
    "GetAssignment": get_assignment,
    "ApproveAssignment": approve_assignment,
    "RejectAssignment": reject_assignment,
    "SendBonus": _no_output(payments.send_bonus),
    "ListBonusPayments": _listing("BonusPayments", payments.list_bonus_payments, bonus_view),
    "GetAccountBalance": get_account_balance,
    "CreateQualificationType": create_qualification_type,
    "GetQualificationType": get_qualification_type,
    "AssociateQualificationWithWorker": _no_output(qualifications.associate),
    "DisassociateQualificationFromWorker": _no_output(qualifications.disassociate),
    "ListWorkersWithQualificationType": _listing("Qualifications", qualifications.list_workers,
                                                  qualification_view),
    "CreateWorkerBlock": create_worker_block,
    "DeleteWorkerBlock": delete_worker_block,
    "NotifyWorkers": notify_workers,
}
