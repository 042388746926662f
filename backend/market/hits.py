"""Requester operations on HIT types and HITs: publish, read, list, extend, expire, delete."""

from __future__ import annotations

import hashlib
import json
from datetime import UTC, datetime, timedelta
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import selectinload

from backend.market import lifecycle, tokens
from backend.market.context import Call, new_id
from backend.market.errors import (
    HIT_ALREADY_EXISTS,
    HIT_DOES_NOT_EXIST,
    HIT_TYPE_DOES_NOT_EXIST,
    INVALID_ASSIGNMENT_INCREASE,
    INVALID_HIT_STATE,
    RequestError,
    invalid,
    not_found,
)
from backend.market.lifecycle import HitState
from backend.market.models import Hit, HitType
from backend.market.money import LARGE_HIT_ASSIGNMENTS, parse_amount
from backend.market.pagination import decode, encode, page, page_size
from backend.market.questions import validate_question
from backend.market.requirements import check_requirements

# MTurk's documented limits.
MIN_DURATION_S, MAX_DURATION_S = 30, 365 * 24 * 3600
MAX_AUTO_APPROVAL_DELAY_S = 30 * 24 * 3600
DEFAULT_AUTO_APPROVAL_DELAY_S = MAX_AUTO_APPROVAL_DELAY_S
MAX_ASSIGNMENTS = 1_000_000
MAX_TITLE, MAX_DESCRIPTION, MAX_KEYWORDS, MAX_ANNOTATION = 128, 2000, 1000, 255
MAX_EXTENSION = timedelta(days=365)
_SCAN_BATCH = 200


def _check_range(params: dict[str, Any], member: str, low: int, high: int) -> None:
    value = params.get(member)
    if value is not None and not low <= value <= high:
        raise invalid(f"{member} must be between {low} and {high}, got {value}")


def _check_text(params: dict[str, Any], member: str, limit: int, required: bool) -> None:
    value = params.get(member)
    if required and not (value or "").strip():
        raise invalid(f"{member} must not be empty")
    if value is not None and len(value) > limit:
        raise invalid(f"{member} may be at most {limit} characters, got {len(value)}")


def _type_properties(call: Call, params: dict[str, Any]) -> dict[str, Any]:
    _check_text(params, "Title", MAX_TITLE, required=True)
    _check_text(params, "Description", MAX_DESCRIPTION, required=True)
    _check_text(params, "Keywords", MAX_KEYWORDS, required=False)
    _check_range(params, "AssignmentDurationInSeconds", MIN_DURATION_S, MAX_DURATION_S)
    _check_range(params, "AutoApprovalDelayInSeconds", 0, MAX_AUTO_APPROVAL_DELAY_S)
    requirements = params.get("QualificationRequirements") or []
    check_requirements(call.session, requirements)
    return {
        "title": params["Title"], "description": params["Description"],
        "keywords": params.get("Keywords"),
        "reward_cents": _reward_cents(call, params["Reward"]),
        "assignment_duration_s": params["AssignmentDurationInSeconds"],
        "auto_approval_delay_s": params.get(
            "AutoApprovalDelayInSeconds", DEFAULT_AUTO_APPROVAL_DELAY_S),
        "qualification_requirements": requirements,
    }


def _reward_cents(call: Call, text: str) -> int:
    """A HIT's reward in cents: at least one, as on MTurk (an assignment that pays nothing is
    refused), except from an unpaid requester account (the team crowd's), whose HITs may pay
    0."""
    cents = parse_amount(text, "Reward")
    if cents < 1 and not call.requester.unpaid:
        raise invalid(f"Reward {text} is less than the smallest reward, 0.01")
    return cents


def find_or_create_hit_type(call: Call, params: dict[str, Any]) -> HitType:
    """The requester's HIT type with exactly these properties, made if it does not exist."""
    props = _type_properties(call, params)
    fingerprint = hashlib.sha256(json.dumps(props, sort_keys=True).encode()).hexdigest()
    stmt = select(HitType).where(HitType.requester == call.requester_id,
                                 HitType.fingerprint == fingerprint)
    hit_type = call.session.scalars(stmt).one_or_none()
    if hit_type is None:
        hit_type = HitType(type_id=new_id("3"), group_id=new_id("3"),
                           requester=call.requester_id, fingerprint=fingerprint,
                           created_at=call.now, **props)
        call.session.add(hit_type)
        call.session.flush()
    return hit_type


def get_hit_type_or_raise(call: Call, type_id: str) -> HitType:
    stmt = select(HitType).where(HitType.type_id == type_id,
                                 HitType.requester == call.requester_id)
    hit_type = call.session.scalars(stmt).one_or_none()
    if hit_type is None:
        raise not_found("HIT type", type_id, HIT_TYPE_DOES_NOT_EXIST)
    return hit_type


def _refuse_unsupported(params: dict[str, Any]) -> None:
    for member in ("AssignmentReviewPolicy", "HITReviewPolicy"):
        if params.get(member) is not None:
            raise invalid(f"{member}: review policies are not supported by this marketplace")
    if params.get("HITLayoutId") is not None or params.get("HITLayoutParameters"):
        raise invalid("HITLayoutId: HIT layouts are not supported by this marketplace; "
                      "send the Question document instead")
    if params.get("Question") is None:
        raise invalid("Question is required (an ExternalQuestion, HTMLQuestion or QuestionForm)")


def create_hit(call: Call, hit_type: HitType, params: dict[str, Any]) -> tuple[Hit, HitState]:
    """Publish a HIT of ``hit_type``, holding its rewards and fees from the balance."""
    token = params.get("UniqueRequestToken")
    earlier = tokens.find(call, "CreateHIT", token)
    if earlier is not None:
        raise RequestError(
            f'A HIT was already created with UniqueRequestToken "{token}": HITId '
            f"{earlier.entity_id} (request {earlier.request_id}).", HIT_ALREADY_EXISTS)
    _refuse_unsupported(params)
    _check_range(params, "LifetimeInSeconds", MIN_DURATION_S, MAX_DURATION_S)
    _check_range(params, "MaxAssignments", 1, MAX_ASSIGNMENTS)
    _check_text(params, "RequesterAnnotation", MAX_ANNOTATION, required=False)
    validate_question(params["Question"])
    hit = Hit(hit_id=new_id("3"), requester=call.requester_id, hit_type=hit_type,
              question=params["Question"], requester_annotation=params.get("RequesterAnnotation"),
              max_assignments=params.get("MaxAssignments") or 1, created_at=call.now,
              expiration=call.now + timedelta(seconds=params["LifetimeInSeconds"]),
              reviewing=False, held_slots=0, settled=False, assignments=[])
    call.session.add(hit)
    call.session.flush()
    state = lifecycle.refresh_hit(call.session, hit, call.now, payer=call.requester)
    tokens.remember(call, "CreateHIT", token, hit.hit_id)
    return hit, state


def get_hit_or_raise(call: Call, hit_id: str) -> tuple[Hit, HitState]:
    """The requester's own HIT, with what the clock made due applied."""
    stmt = (select(Hit).where(Hit.hit_id == hit_id, Hit.requester == call.requester_id)
            .options(selectinload(Hit.assignments), selectinload(Hit.hit_type)))
    hit = call.session.scalars(stmt).one_or_none()
    if hit is None:
        raise not_found("Hit", hit_id, HIT_DOES_NOT_EXIST)
    return hit, lifecycle.refresh_hit(call.session, hit, call.now)


def list_hits(call: Call, params: dict[str, Any]) -> tuple[list[tuple[Hit, HitState]], str | None]:
    """The requester's HITs except deleted ones, oldest first."""
    stmt = (select(Hit).where(Hit.requester == call.requester_id, Hit.disposed_at.is_(None))
            .options(selectinload(Hit.assignments), selectinload(Hit.hit_type)))
    hits, next_token = page(call.session, stmt, Hit.id, "ListHITs", params)
    return [(hit, lifecycle.refresh_hit(call.session, hit, call.now)) for hit in hits], next_token


def list_reviewable_hits(
    call: Call, params: dict[str, Any]
) -> tuple[list[tuple[Hit, HitState]], str | None]:
    """HITs in the Reviewable (default) or Reviewing status, optionally of one HIT type."""
    wanted = params.get("Status") or "Reviewable"
    size, after = page_size(params), decode("ListReviewableHITs", params.get("NextToken"))
    stmt = (select(Hit).where(Hit.requester == call.requester_id, Hit.disposed_at.is_(None))
            .options(selectinload(Hit.assignments), selectinload(Hit.hit_type))
            .order_by(Hit.id).limit(_SCAN_BATCH))
    if params.get("HITTypeId"):
        stmt = stmt.join(Hit.hit_type).where(HitType.type_id == params["HITTypeId"])
    found: list[tuple[Hit, HitState]] = []
    while len(found) <= size:
        batch = list(call.session.scalars(stmt.where(Hit.id > after)))
        for hit in batch:
            state = lifecycle.refresh_hit(call.session, hit, call.now)
            if state.status == wanted:
                found.append((hit, state))
        if len(batch) < _SCAN_BATCH:
            break
        after = batch[-1].id
    if len(found) <= size:
        return found, None
    return found[:size], encode("ListReviewableHITs", found[size - 1][0].id)


def _refuse_disposed(hit: Hit, state: HitState, operation: str) -> None:
    if state.status == "Disposed":
        raise RequestError(f"HIT {hit.hit_id} has been deleted; {operation} cannot change it.",
                           INVALID_HIT_STATE)


def update_expiration(call: Call, hit_id: str, expire_at: float) -> None:
    """Expire the HIT now (a time not in the future) or move its expiration later."""
    hit, state = get_hit_or_raise(call, hit_id)
    _refuse_disposed(hit, state, "UpdateExpirationForHIT")
    when = datetime.fromtimestamp(expire_at, UTC)
    if when > call.now + MAX_EXTENSION:
        raise invalid(f"ExpireAt may be at most {MAX_EXTENSION.days} days from now")
    if when <= call.now:
        hit.expiration = min(hit.expiration, call.now)
    else:
        hit.expiration = when
        hit.reviewing = False
    lifecycle.refresh_hit(call.session, hit, call.now, payer=call.requester)


def update_review_status(call: Call, hit_id: str, revert: bool) -> None:
    """Reviewable -> Reviewing, or with ``revert`` Reviewing -> Reviewable."""
    hit, state = get_hit_or_raise(call, hit_id)
    source, target = ("Reviewing", "Reviewable") if revert else ("Reviewable", "Reviewing")
    if state.status != source:
        raise RequestError(
            f"HIT {hit_id} is {state.status}; only a {source} HIT can become {target}.",
            INVALID_HIT_STATE)
    hit.reviewing = not revert
    call.session.flush()


def delete_hit(call: Call, hit_id: str) -> None:
    """Dispose of a Reviewable HIT whose submitted assignments are all approved or rejected.

    Deleting an already deleted HIT succeeds, so a retried call is harmless.
    """
    hit, state = get_hit_or_raise(call, hit_id)
    if state.status == "Disposed":
        return
    if state.status not in ("Reviewable", "Reviewing"):
        raise RequestError(
            f"HIT {hit_id} is {state.status}; only a Reviewable HIT (expired, or with every "
            "assignment submitted) can be deleted.", INVALID_HIT_STATE)
    if state.submitted:
        raise RequestError(
            f"HIT {hit_id} has {state.submitted} submitted assignment(s) not yet approved or "
            "rejected; review them before deleting the HIT.", INVALID_HIT_STATE)
    hit.disposed_at = call.now
    lifecycle.refresh_hit(call.session, hit, call.now)


def add_assignments(call: Call, hit_id: str, count: int, token: str | None) -> None:
    """Raise MaxAssignments by ``count``, holding the extra rewards and fees."""
    tokens.refuse_replay(call, "CreateAdditionalAssignmentsForHIT", token)
    hit, state = get_hit_or_raise(call, hit_id)
    _refuse_disposed(hit, state, "CreateAdditionalAssignmentsForHIT")
    if count < 1:
        raise invalid(f"NumberOfAdditionalAssignments must be at least 1, got {count}")
    total = hit.max_assignments + count
    if total > MAX_ASSIGNMENTS:
        raise invalid(f"a HIT may have at most {MAX_ASSIGNMENTS} assignments")
    if hit.max_assignments < LARGE_HIT_ASSIGNMENTS <= total:
        raise RequestError(
            f"HIT {hit_id} has {hit.max_assignments} assignments; a HIT created with fewer than "
            f"{LARGE_HIT_ASSIGNMENTS} cannot be extended to {LARGE_HIT_ASSIGNMENTS} or more.",
            INVALID_ASSIGNMENT_INCREASE)
    hit.max_assignments = total
    lifecycle.refresh_hit(call.session, hit, call.now, payer=call.requester)
    tokens.remember(call, "CreateAdditionalAssignmentsForHIT", token, hit.hit_id)
