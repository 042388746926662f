"""The requester API: one handler per MTurk operation, from validated input to wire output.

Handlers only translate: the rules live in hits, assignments, payments, qualifications and
blocks. Every handler receives input that already matches the operation's input shape.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from backend.market import assignments, blocks, hits, payments, qualifications
from backend.market.context import Call
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


def list_hits(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    found, next_token = hits.list_hits(call, params)
    return page_result("HITs", [hit_view(*item) for item in found], next_token)


def list_reviewable_hits(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    found, next_token = hits.list_reviewable_hits(call, params)
    return page_result("HITs", [hit_view(*item) for item in found], next_token)


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


def list_assignments_for_hit(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    found, next_token = assignments.list_for_hit(call, params)
    return page_result("Assignments", [assignment_view(a) for a in found], next_token)


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


def send_bonus(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    payments.send_bonus(call, params)
    return EMPTY


def list_bonus_payments(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    found, next_token = payments.list_bonus_payments(call, params)
    return page_result("BonusPayments", [bonus_view(b) for b in found], next_token)


def get_account_balance(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    return payments.account_balance(call)


def create_qualification_type(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    return {"QualificationType": qualification_type_view(
        qualifications.create_type(call, params))}


def get_qualification_type(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    return {"QualificationType": qualification_type_view(
        qualifications.get_type_or_raise(call, params["QualificationTypeId"]))}


def associate_qualification_with_worker(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    qualifications.associate(call, params)
    return EMPTY


def disassociate_qualification_from_worker(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    qualifications.disassociate(call, params)
    return EMPTY


def list_workers_with_qualification_type(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    found, next_token = qualifications.list_workers(call, params)
    return page_result("Qualifications", [qualification_view(q) for q in found], next_token)


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
    "ListHITs": list_hits,
    "ListReviewableHITs": list_reviewable_hits,
    "UpdateExpirationForHIT": update_expiration_for_hit,
    "UpdateHITReviewStatus": update_hit_review_status,
    "DeleteHIT": delete_hit,
    "CreateAdditionalAssignmentsForHIT": create_additional_assignments_for_hit,
    "ListAssignmentsForHIT": list_assignments_for_hit,
    "GetAssignment": get_assignment,
    "ApproveAssignment": approve_assignment,
    "RejectAssignment": reject_assignment,
    "SendBonus": send_bonus,
    "ListBonusPayments": list_bonus_payments,
    "GetAccountBalance": get_account_balance,
    "CreateQualificationType": create_qualification_type,
    "GetQualificationType": get_qualification_type,
    "AssociateQualificationWithWorker": associate_qualification_with_worker,
    "DisassociateQualificationFromWorker": disassociate_qualification_from_worker,
    "ListWorkersWithQualificationType": list_workers_with_qualification_type,
    "CreateWorkerBlock": create_worker_block,
    "DeleteWorkerBlock": delete_worker_block,
    "NotifyWorkers": notify_workers,
}
