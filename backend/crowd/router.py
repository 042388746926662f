"""Admin endpoints of the crowd: publish, sync, review, HIT and worker actions, costs.

Each action goes to the crowd provider of the row it acts on (a publish: the request's
``provider``, else the setting's; a worker action: the setting's)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query
from sqlalchemy import select

from backend.accounts.deps import CurrentAdmin
from backend.annotation import service as tasks
from backend.annotation.models import Assignment
from backend.annotation.schemas import StartRequest
from backend.annotation.tokens import PREVIEW_ASSIGNMENT_ID, TASK_SCOPE, assignment_token
from backend.config import get_settings
from backend.crowd import actions, flows, holds, pricing
from backend.crowd.completion import StartRead, completion_for
from backend.crowd.costs import costs
from backend.crowd.models import CrowdHit
from backend.crowd.schemas import (
    AddAssignmentsRequest,
    BlockRequest,
    BonusRequest,
    CostsRead,
    ExtendRequest,
    NotifyRequest,
    PaymentRead,
    PublishOptions,
    PublishRequest,
    PublishResult,
    QualificationRequest,
)
from backend.db import SessionDep, session_scope
from backend.errors import Forbidden, Unauthorized
from backend.middleware import JSONBodyRoute
from backend.security import verify_token
from backend.validation import Id, Key, QueryKey

router = APIRouter(prefix="/api/crowd", tags=["crowd"])


def _hit_read(hit: Any) -> dict[str, Any]:
    return {"hit_id": hit.hit_id, "task_id": hit.task_id, "round": hit.round,
            "max_assignments": hit.max_assignments,
            "reward": pricing.cents_to_dollars(hit.reward_cents),
            "expired": hit.expired_at is not None}


@router.post("/publish", response_model=PublishResult)
def publish(body: PublishRequest, session: SessionDep, _: CurrentAdmin) -> PublishResult:
    options = PublishOptions.model_validate(body.model_dump(exclude={"sequence_id", "dry_run"}))
    if body.dry_run:
        return flows.plan(session, options, body.sequence_id)
    return flows.publish(session, None, options, body.sequence_id)


@router.post("/assignments/{assignment_id}/bonus", response_model=PaymentRead)
def bonus(assignment_id: Id, body: BonusRequest, _: CurrentAdmin) -> PaymentRead:
    # The flow commits its own units of work: the ledger row before paying, and after.
    return flows.pay_bonus(None, assignment_id, pricing.dollars_to_cents(body.amount),
                           body.reason, body.key)


@router.post("/hits/{hit_id}/extend")
def extend_hit(hit_id: Key, body: ExtendRequest, session: SessionDep,
               _: CurrentAdmin) -> dict[str, Any]:
    return _hit_read(actions.extend_hit(session, None, hit_id, body.seconds))


@router.post("/hits/{hit_id}/expire")
def expire_hit(hit_id: Key, session: SessionDep, _: CurrentAdmin) -> dict[str, Any]:
    return _hit_read(actions.expire_hit(session, None, hit_id))


@router.post("/hits/{hit_id}/assignments")
def add_assignments(hit_id: Key, body: AddAssignmentsRequest, session: SessionDep,
                    _: CurrentAdmin) -> dict[str, Any]:
    hit = actions.add_assignments(session, None, hit_id, body.count, body.allow_large_hits)
    return _hit_read(hit)


@router.post("/workers/{worker_id}/qualifications")
def grant(worker_id: Key, body: QualificationRequest, session: SessionDep,
          _: CurrentAdmin) -> dict[str, str]:
    type_id = actions.grant_qualification(session, None, worker_id, body.qualification_type_id,
                                          body.value, body.notify)
    return {"worker_id": worker_id, "qualification_type_id": type_id, "state": "granted"}


@router.delete("/workers/{worker_id}/qualifications")
def revoke(worker_id: Key, session: SessionDep, _: CurrentAdmin,
           qualification_type_id: QueryKey = None) -> dict[str, str]:
    type_id = actions.revoke_qualification(session, None, worker_id, qualification_type_id)
    return {"worker_id": worker_id, "qualification_type_id": type_id, "state": "revoked"}


@router.post("/workers/{worker_id}/block")
def block(worker_id: Key, body: BlockRequest, session: SessionDep,
          _: CurrentAdmin) -> dict[str, str]:
    actions.block_worker(session, None, worker_id, body.reason)
    return {"worker_id": worker_id, "state": "blocked"}


@router.delete("/workers/{worker_id}/block")
def unblock(worker_id: Key, session: SessionDep, _: CurrentAdmin,
            reason: Annotated[str | None, Query(max_length=1024)] = None) -> dict[str, str]:
    actions.unblock_worker(session, None, worker_id, reason)
    return {"worker_id": worker_id, "state": "unblocked"}


@router.post("/notify")
def notify(body: NotifyRequest, _: CurrentAdmin) -> dict[str, Any]:
    failures = actions.notify_workers(None, body.worker_ids, body.subject, body.message)
    return {"sent": len(body.worker_ids) - len(failures), "failures": failures}


@router.get("/costs", response_model=CostsRead)
def read_costs(session: SessionDep, _: CurrentAdmin) -> CostsRead:
    return costs(session)


# ----- the annotation page's start: a HIT's assignment, confirmed by the marketplace --------

# Its routes answer the worker's page, under /api like the page's other routes.
page_router = APIRouter(prefix="/api", tags=["annotation"], route_class=JSONBodyRoute)


def unit_named(task_id: int, named: str) -> str:
    """The unit the page's address names: its HIT id (MTurk, the team), or, for a page whose
    address carries its batch's id instead (Prolific's STUDY_ID; a unit there is
    "<study id>:<position>"), this task's unit in that batch; else ``named`` as it is."""
    with session_scope() as session:
        found = list(session.scalars(select(CrowdHit.hit_id).where(
            CrowdHit.task_id == task_id,
            (CrowdHit.hit_id == named)
            | CrowdHit.hit_id.startswith(f"{named}:", autoescape=True))))
    return found[0] or named if len(found) == 1 else named


def _opened_before(task_id: int, body: StartRequest) -> bool:
    """Whether the assignment was opened here before (then for this task, worker and HIT);
    read in a unit of work of its own, closed before the marketplace is asked."""
    with session_scope() as session:
        tasks.get_task_or_raise(session, task_id)
        ours = session.scalars(select(Assignment).where(
            Assignment.external_id == body.assignment_id)).one_or_none()
        if ours is None:
            return False
        if (ours.task_id, ours.worker_id, ours.hit_id) != (task_id, body.worker_id,
                                                           body.hit_id):
            raise Forbidden(f"assignment {body.assignment_id} belongs to another task, worker "
                            "or HIT")
        return True


@page_router.post("/annotate/start", response_model=StartRead)
def start(body: StartRequest, session: SessionDep) -> StartRead:
    """Exchange a HIT's task token and the marketplace's ids for an assignment token, and
    say how the page completes (``completion``: the HIT's provider decides).

    Only a marketplace assignment is started here, and only one the marketplace confirms
    (backend.crowd.holds): its HIT shows this task and a worker holds an assignment of it, or
    the marketplace's record of the assignment names that HIT and worker (a Prolific page
    sends its STUDY_ID as the HIT id: ``unit_named`` finds the task's unit). A direct link
    (no HIT) is made by an admin only (POST /api/tasks/{id}/assignments). 403/404 say why an
    assignment is refused; 503 when the marketplace cannot be reached.
    """
    if body.assignment_id == PREVIEW_ASSIGNMENT_ID:
        raise Unauthorized("the HIT is not accepted yet (preview)")
    claims = verify_token(body.task_token, get_settings().signing_key, TASK_SCOPE)
    task_id = int(claims["task_id"])
    if not body.hit_id:
        raise Forbidden("no HIT id: an assignment starts here only from its marketplace HIT "
                        "(hitId, assignmentId and workerId in the page address); a direct "
                        "link is made by an admin (POST /api/tasks/{id}/assignments)")
    hit_id = unit_named(task_id, body.hit_id)
    body = body.model_copy(update={"hit_id": hit_id})
    if not _opened_before(task_id, body):
        slots = holds.confirm_held(task_id, hit_id, body.assignment_id, body.worker_id)
        if slots is not None:
            tasks.require_open_slot(session, hit_id, slots.held, slots.duration_s)
    task = tasks.get_task_or_raise(session, task_id)
    assignment = tasks.start_assignment(session, task, body.assignment_id, body.worker_id,
                                          hit_id)
    # The assignment's ids are those of the provider that published its HIT.
    provider = session.scalar(select(CrowdHit.provider).where(CrowdHit.hit_id == hit_id))
    if provider is not None and assignment.provider != provider:
        assignment.provider = provider
    return StartRead(token=assignment_token(task, assignment),
                     completion=completion_for(session, hit_id, body.assignment_id))
