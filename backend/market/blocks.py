"""Requester operations on workers: blocking them and messaging them."""

from __future__ import annotations

from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.market.context import Call
from backend.market.errors import invalid
from backend.market.models import Hit, MarketAssignment, Notification, WorkerBlock

MAX_SUBJECT, MAX_MESSAGE, MAX_RECIPIENTS = 200, 4096, 100


def create_block(call: Call, worker_id: str, reason: str) -> WorkerBlock:
    """Keep ``worker_id`` off this requester's HITs; blocking again updates the reason."""
    if not reason.strip():
        raise invalid("Reason must not be empty")
    stmt = select(WorkerBlock).where(WorkerBlock.requester == call.requester_id,
                                     WorkerBlock.worker_id == worker_id)
    block = call.session.scalars(stmt).one_or_none()
    if block is None:
        block = WorkerBlock(requester=call.requester_id, worker_id=worker_id, created_at=call.now)
        call.session.add(block)
    block.reason = reason
    call.session.flush()
    return block


def delete_block(call: Call, worker_id: str) -> None:
    """Lift a block; lifting one that does not exist succeeds, as MTurk documents."""
    stmt = select(WorkerBlock).where(WorkerBlock.requester == call.requester_id,
                                     WorkerBlock.worker_id == worker_id)
    block = call.session.scalars(stmt).one_or_none()
    if block is not None:
        call.session.delete(block)
        call.session.flush()


def blocked_requesters(session: Session, worker_id: str) -> set[str]:
    """Requesters who blocked ``worker_id``."""
    stmt = select(WorkerBlock.requester).where(WorkerBlock.worker_id == worker_id)
    return set(session.scalars(stmt))


def _reviewed_workers(call: Call, worker_ids: list[str]) -> set[str]:
    stmt = (select(MarketAssignment.worker_id).join(MarketAssignment.hit)
            .where(Hit.requester == call.requester_id, MarketAssignment.worker_id.in_(worker_ids),
                   MarketAssignment.status.in_(("Approved", "Rejected"))).distinct())
    return set(call.session.scalars(stmt))


def notify_workers(call: Call, params: dict[str, Any]) -> list[dict[str, str]]:
    """Message workers whose work this requester has approved or rejected before (MTurk's
    rule); every other worker comes back as a HardFailure."""
    subject, text, worker_ids = params["Subject"], params["MessageText"], params["WorkerIds"]
    if not subject.strip() or len(subject) > MAX_SUBJECT:
        raise invalid(f"Subject must be 1 to {MAX_SUBJECT} characters")
    if not text.strip() or len(text) > MAX_MESSAGE:
        raise invalid(f"MessageText must be 1 to {MAX_MESSAGE} characters")
    if not 1 <= len(worker_ids) <= MAX_RECIPIENTS:
        raise invalid(f"WorkerIds must list 1 to {MAX_RECIPIENTS} workers")
    reviewed = _reviewed_workers(call, worker_ids)
    failures = []
    for worker_id in dict.fromkeys(worker_ids):
        if worker_id in reviewed:
            call.session.add(Notification(requester=call.requester_id, worker_id=worker_id,
                                          subject=subject, message=text, sent_at=call.now))
        else:
            failures.append({
                "NotifyWorkersFailureCode": "HardFailure",
                "NotifyWorkersFailureMessage": "You can notify only workers whose work you "
                                               "have approved or rejected.",
                "WorkerId": worker_id})
    call.session.flush()
    return failures
