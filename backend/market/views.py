"""Records in their MTurk wire form (the output shapes of the service model)."""

from __future__ import annotations

from typing import Any

from backend.market.context import epoch
from backend.market.lifecycle import HitState
from backend.market.models import Bonus, Hit, MarketAssignment, Qualification, QualificationType
from backend.market.money import format_amount


def _compact(data: dict[str, Any]) -> dict[str, Any]:
    return {key: value for key, value in data.items() if value is not None}


def hit_view(hit: Hit, state: HitState) -> dict[str, Any]:
    hit_type = hit.hit_type
    return _compact({
        "HITId": hit.hit_id,
        "HITTypeId": hit_type.type_id,
        "HITGroupId": hit_type.group_id,
        "CreationTime": epoch(hit.created_at),
        "Title": hit_type.title,
        "Description": hit_type.description,
        "Question": hit.question,
        "Keywords": hit_type.keywords,
        "HITStatus": state.status,
        "MaxAssignments": hit.max_assignments,
        "Reward": format_amount(hit_type.reward_cents),
        "AutoApprovalDelayInSeconds": hit_type.auto_approval_delay_s,
        "Expiration": epoch(hit.expiration),
        "AssignmentDurationInSeconds": hit_type.assignment_duration_s,
        "RequesterAnnotation": hit.requester_annotation,
        "QualificationRequirements": hit_type.qualification_requirements,
        # Review policies are not run here, so no HIT is ever marked for review.
        "HITReviewStatus": "NotReviewed",
        "NumberOfAssignmentsPending": state.pending,
        "NumberOfAssignmentsAvailable": state.available,
        "NumberOfAssignmentsCompleted": state.completed,
    })


def assignment_view(assignment: MarketAssignment) -> dict[str, Any]:
    return _compact({
        "AssignmentId": assignment.assignment_id,
        "WorkerId": assignment.worker_id,
        "HITId": assignment.hit.hit_id,
        "AssignmentStatus": assignment.status,
        "AutoApprovalTime": epoch(assignment.auto_approval_time),
        "AcceptTime": epoch(assignment.accept_time),
        "SubmitTime": epoch(assignment.submit_time),
        "ApprovalTime": epoch(assignment.approval_time),
        "RejectionTime": epoch(assignment.rejection_time),
        "Deadline": epoch(assignment.deadline),
        "Answer": assignment.answer,
        "RequesterFeedback": assignment.requester_feedback,
    })


def bonus_view(bonus: Bonus) -> dict[str, Any]:
    return _compact({
        "WorkerId": bonus.worker_id,
        "BonusAmount": format_amount(bonus.amount_cents),
        "AssignmentId": bonus.assignment.assignment_id,
        "Reason": bonus.reason,
        "GrantTime": epoch(bonus.grant_time),
    })


def qualification_type_view(qtype: QualificationType) -> dict[str, Any]:
    return _compact({
        "QualificationTypeId": qtype.type_id,
        "CreationTime": epoch(qtype.created_at),
        "Name": qtype.name,
        "Description": qtype.description,
        "Keywords": qtype.keywords,
        "QualificationTypeStatus": qtype.status,
        "Test": qtype.test,
        "TestDurationInSeconds": qtype.test_duration_s,
        "AnswerKey": qtype.answer_key,
        "RetryDelayInSeconds": qtype.retry_delay_s,
        "IsRequestable": qtype.test is not None or qtype.auto_granted,
        "AutoGranted": qtype.auto_granted,
        "AutoGrantedValue": qtype.auto_granted_value if qtype.auto_granted else None,
    })


def qualification_view(qualification: Qualification) -> dict[str, Any]:
    return _compact({
        "QualificationTypeId": qualification.qualification_type.type_id,
        "WorkerId": qualification.worker_id,
        "GrantTime": epoch(qualification.grant_time),
        "IntegerValue": qualification.integer_value,
        "Status": qualification.status,
    })
