"""Admin endpoints of the crowd: publish, sync, review, HIT and worker actions, costs."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query

from backend import pipeline
from backend.accounts.deps import CurrentAdmin
from backend.config import get_settings
from backend.crowd import actions, flows, pricing, workers
from backend.crowd.client import MTurkClient, make_client
from backend.crowd.costs import costs
from backend.crowd.schemas import (
    AddAssignmentsRequest,
    ApproveRequest,
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
    RejectRequest,
    SyncResult,
    WorkerDetailRead,
    WorkerStatsRead,
)
from backend.db import SessionDep
from backend.validation import Id, Key, Offset, QueryKey

router = APIRouter(prefix="/api/crowd", tags=["crowd"])


def get_mturk() -> MTurkClient:
    return make_client(get_settings())


MTurk = Annotated[MTurkClient, Depends(get_mturk)]


def _hit_read(hit: Any) -> dict[str, Any]:
    return {"hit_id": hit.hit_id, "task_id": hit.task_id, "round": hit.round,
            "max_assignments": hit.max_assignments,
            "reward": pricing.cents_to_dollars(hit.reward_cents),
            "expired": hit.expired_at is not None}


@router.post("/publish", response_model=PublishResult)
def publish(body: PublishRequest, session: SessionDep, _: CurrentAdmin,
            client: MTurk) -> PublishResult:
    options = PublishOptions.model_validate(body.model_dump(exclude={"sequence_id", "dry_run"}))
    if body.dry_run:
        return flows.plan(session, options, body.sequence_id)
    return flows.publish(session, client, options, body.sequence_id)


@router.post("/sync", response_model=SyncResult)
def sync_submissions(session: SessionDep, _: CurrentAdmin, client: MTurk) -> SyncResult:
    return pipeline.sync(session, client)


@router.post("/assignments/{assignment_id}/approve", response_model=PaymentRead)
def approve(assignment_id: Id, body: ApproveRequest, session: SessionDep, _: CurrentAdmin,
            client: MTurk) -> PaymentRead:
    return pipeline.approve(session, client, assignment_id, body.feedback)


@router.post("/assignments/{assignment_id}/reject", response_model=PaymentRead)
def reject(assignment_id: Id, body: RejectRequest, session: SessionDep, _: CurrentAdmin,
           client: MTurk) -> PaymentRead:
    return pipeline.reject(session, client, assignment_id, body.feedback)


@router.post("/assignments/{assignment_id}/bonus", response_model=PaymentRead)
def bonus(assignment_id: Id, body: BonusRequest, _: CurrentAdmin, client: MTurk) -> PaymentRead:
    # The flow commits its own units of work: the ledger row before paying, and after.
    return flows.pay_bonus(client, assignment_id, pricing.dollars_to_cents(body.amount),
                           body.reason, body.key)


@router.post("/hits/{hit_id}/extend")
def extend_hit(hit_id: Key, body: ExtendRequest, session: SessionDep, _: CurrentAdmin,
               client: MTurk) -> dict[str, Any]:
    return _hit_read(actions.extend_hit(session, client, hit_id, body.seconds))


@router.post("/hits/{hit_id}/expire")
def expire_hit(hit_id: Key, session: SessionDep, _: CurrentAdmin,
               client: MTurk) -> dict[str, Any]:
    return _hit_read(actions.expire_hit(session, client, hit_id))


@router.post("/hits/{hit_id}/assignments")
def add_assignments(hit_id: Key, body: AddAssignmentsRequest, session: SessionDep,
                    _: CurrentAdmin, client: MTurk) -> dict[str, Any]:
    hit = actions.add_assignments(session, client, hit_id, body.count, body.allow_large_hits)
    return _hit_read(hit)


@router.get("/workers", response_model=list[WorkerStatsRead])
def list_workers(session: SessionDep, _: CurrentAdmin, limit: int = Query(200, ge=1, le=1000),
                 offset: Offset = 0) -> list[WorkerStatsRead]:
    """Workers by id, ``limit`` (200, at most 1,000) from ``offset`` on: approval rate, median
    error, working time, earnings, block, and their newest QC reports by date."""
    return workers.list_workers(session, limit, offset)


@router.get("/workers/{worker_id}", response_model=WorkerDetailRead)
def read_worker(worker_id: Key, session: SessionDep, _: CurrentAdmin) -> WorkerDetailRead:
    """One worker's stats, every QC report by date and their newest assignments (404 for a
    worker with no work and no block here)."""
    return workers.get_worker_or_raise(session, worker_id)


@router.post("/workers/{worker_id}/qualifications")
def grant(worker_id: Key, body: QualificationRequest, session: SessionDep, _: CurrentAdmin,
          client: MTurk) -> dict[str, str]:
    type_id = actions.grant_qualification(session, client, worker_id, body.qualification_type_id,
                                          body.value, body.notify)
    return {"worker_id": worker_id, "qualification_type_id": type_id, "state": "granted"}


@router.delete("/workers/{worker_id}/qualifications")
def revoke(worker_id: Key, session: SessionDep, _: CurrentAdmin, client: MTurk,
           qualification_type_id: QueryKey = None) -> dict[str, str]:
    type_id = actions.revoke_qualification(session, client, worker_id, qualification_type_id)
    return {"worker_id": worker_id, "qualification_type_id": type_id, "state": "revoked"}


@router.post("/workers/{worker_id}/block")
def block(worker_id: Key, body: BlockRequest, session: SessionDep, _: CurrentAdmin,
          client: MTurk) -> dict[str, str]:
    actions.block_worker(session, client, worker_id, body.reason)
    return {"worker_id": worker_id, "state": "blocked"}


@router.delete("/workers/{worker_id}/block")
def unblock(worker_id: Key, session: SessionDep, _: CurrentAdmin, client: MTurk,
            reason: Annotated[str | None, Query(max_length=1024)] = None) -> dict[str, str]:
    actions.unblock_worker(session, client, worker_id, reason)
    return {"worker_id": worker_id, "state": "unblocked"}


@router.post("/notify")
def notify(body: NotifyRequest, _: CurrentAdmin, client: MTurk) -> dict[str, Any]:
    failures = actions.notify_workers(client, body.worker_ids, body.subject, body.message)
    return {"sent": len(body.worker_ids) - len(failures), "failures": failures}


@router.get("/costs", response_model=CostsRead)
def read_costs(session: SessionDep, _: CurrentAdmin) -> CostsRead:
    return costs(session)
