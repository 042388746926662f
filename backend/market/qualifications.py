"""Requester operations on qualification types and the workers who hold them."""

from __future__ import annotations

from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import selectinload

from backend.market.context import Call, new_id
from backend.market.errors import (
    PERMISSION_DENIED,
    QUALIFICATION_DOES_NOT_EXIST,
    QUALIFICATION_TYPE_DOES_NOT_EXIST,
    QUALIFICATION_TYPE_EXISTS,
    RequestError,
    invalid,
    not_found,
)
from backend.market.models import Notification, Qualification, QualificationType
from backend.market.pagination import page
from backend.market.questions import validate_question

MAX_NAME, MAX_DESCRIPTION, MAX_KEYWORDS = 255, 2000, 1000
DEFAULT_VALUE = 1  # MTurk's default value of a granted qualification


def _check_test(params: dict[str, Any]) -> None:
    test = params.get("Test")
    if test is None:
        if params.get("AnswerKey") is not None:
            raise invalid("AnswerKey needs a Test")
        return
    if params.get("AutoGranted"):
        raise invalid("a qualification type cannot have both a Test and AutoGranted true")
    if params.get("TestDurationInSeconds") is None:
        raise invalid("Test needs TestDurationInSeconds")
    if validate_question(test, "Test") != "QuestionForm":
        raise invalid("Test must be a QuestionForm document")


def create_type(call: Call, params: dict[str, Any]) -> QualificationType:
    name, description = params["Name"].strip(), params["Description"]
    if not name or len(name) > MAX_NAME:
        raise invalid(f"Name must be 1 to {MAX_NAME} characters")
    if len(description) > MAX_DESCRIPTION:
        raise invalid(f"Description may be at most {MAX_DESCRIPTION} characters")
    if len(params.get("Keywords") or "") > MAX_KEYWORDS:
        raise invalid(f"Keywords may be at most {MAX_KEYWORDS} characters")
    for member in ("RetryDelayInSeconds", "TestDurationInSeconds"):
        if (params.get(member) or 0) < 0:
            raise invalid(f"{member} must not be negative")
    _check_test(params)
    taken = call.session.scalar(select(QualificationType.id).where(
        QualificationType.requester == call.requester_id, QualificationType.name == name))
    if taken is not None:
        raise RequestError(f'You already have a qualification type named "{name}"; names are '
                           "unique among a requester's types.", QUALIFICATION_TYPE_EXISTS)
    auto = bool(params.get("AutoGranted"))
    qtype = QualificationType(
        type_id=new_id("3"), requester=call.requester_id, name=name, description=description,
        keywords=params.get("Keywords"), status=params["QualificationTypeStatus"],
        retry_delay_s=params.get("RetryDelayInSeconds"), test=params.get("Test"),
        answer_key=params.get("AnswerKey"),
        test_duration_s=params.get("TestDurationInSeconds"), auto_granted=auto,
        auto_granted_value=params.get("AutoGrantedValue", DEFAULT_VALUE) if auto else None,
        created_at=call.now)
    call.session.add(qtype)
    call.session.flush()
    return qtype


def get_type_or_raise(call: Call, type_id: str, *, own: bool = False) -> QualificationType:
    """A qualification type by id; with ``own`` it must be this requester's."""
    stmt = select(QualificationType).where(QualificationType.type_id == type_id)
    qtype = call.session.scalars(stmt).one_or_none()
    if qtype is None:
        raise not_found("Qualification type", type_id, QUALIFICATION_TYPE_DOES_NOT_EXIST)
    if own and qtype.requester != call.requester_id:
        raise RequestError(f"Qualification type {type_id} belongs to another requester; you "
                           "can only manage types you created.", PERMISSION_DENIED)
    return qtype


def _notify(call: Call, worker_id: str, subject: str, message: str) -> None:
    call.session.add(Notification(requester=call.requester_id, worker_id=worker_id,
                                  subject=subject[:200], message=message, sent_at=call.now))


def associate(call: Call, params: dict[str, Any]) -> Qualification:
    """Grant (or re-grant with a new value) a qualification of the requester's own type."""
    qtype = get_type_or_raise(call, params["QualificationTypeId"], own=True)
    worker_id = params["WorkerId"]
    stmt = select(Qualification).where(Qualification.type_pk == qtype.id,
                                       Qualification.worker_id == worker_id)
    qualification = call.session.scalars(stmt).one_or_none()
    if qualification is None:
        qualification = Qualification(qualification_type=qtype, worker_id=worker_id)
        call.session.add(qualification)
    value = params.get("IntegerValue")
    qualification.integer_value = DEFAULT_VALUE if value is None else value
    qualification.status = "Granted"
    qualification.grant_time = call.now
    qualification.revoke_reason = None
    if params.get("SendNotification", True):
        _notify(call, worker_id, f"Qualification granted: {qtype.name}",
                f"You now hold the qualification {qtype.name} "
                f"(value {qualification.integer_value}).")
    call.session.flush()
    return qualification


def disassociate(call: Call, params: dict[str, Any]) -> Qualification:
    """Revoke a granted qualification; the worker sees ``Reason``."""
    qtype = get_type_or_raise(call, params["QualificationTypeId"], own=True)
    worker_id = params["WorkerId"]
    stmt = select(Qualification).where(Qualification.type_pk == qtype.id,
                                       Qualification.worker_id == worker_id,
                                       Qualification.status == "Granted")
    qualification = call.session.scalars(stmt).one_or_none()
    if qualification is None:
        raise RequestError(f"Worker {worker_id} does not hold qualification {qtype.type_id}.",
                           QUALIFICATION_DOES_NOT_EXIST)
    qualification.status = "Revoked"
    qualification.revoke_reason = params.get("Reason")
    _notify(call, worker_id, f"Qualification revoked: {qtype.name}",
            params.get("Reason") or f"Your qualification {qtype.name} was revoked.")
    call.session.flush()
    return qualification


def list_workers(call: Call, params: dict[str, Any]) -> tuple[list[Qualification], str | None]:
    """Holders of one of the requester's types; ``Status`` narrows to Granted or Revoked."""
    qtype = get_type_or_raise(call, params["QualificationTypeId"], own=True)
    stmt = (select(Qualification).where(Qualification.type_pk == qtype.id)
            .options(selectinload(Qualification.qualification_type)))
    if params.get("Status"):
        stmt = stmt.where(Qualification.status == params["Status"])
    return page(call.session, stmt, Qualification.id, "ListWorkersWithQualificationType", params)
