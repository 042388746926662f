"""HIT and worker actions: extend or expire a HIT, add assignments, qualifications, blocks,
messages. Each is recorded in our database so repeating one is a clear Conflict, not a surprise.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.crowd.client import MTurkClient, call, call_naming
from backend.crowd.models import CrowdHit, CrowdWorkerAction
from backend.crowd.publish import check_assignments, training_qualification
from backend.errors import Conflict, NotFound

# MTurk expires a HIT at once when ExpireAt lies in the past.
_PAST = datetime(2015, 1, 1, tzinfo=UTC)


def get_hit_or_raise(session: Session, hit_id: str) -> CrowdHit:
    row = session.scalar(select(CrowdHit).where(CrowdHit.hit_id == hit_id))
    if row is None:
        raise NotFound(f"no HIT {hit_id} was published from this database")
    return row


def extend_hit(session: Session, client: MTurkClient, hit_id: str, seconds: int) -> CrowdHit:
    """Keep the HIT open ``seconds`` from now (it reopens an expired HIT)."""
    row = get_hit_or_raise(session, hit_id)
    call_naming(client, "update_expiration_for_hit", {"ExpireAt": "seconds"}, HITId=hit_id,
                ExpireAt=datetime.now(UTC) + timedelta(seconds=seconds))
    row.expired_at = None
    session.flush()
    return row


def expire_hit(session: Session, client: MTurkClient, hit_id: str) -> CrowdHit:
    row = get_hit_or_raise(session, hit_id)
    if row.expired_at is not None:
        raise Conflict(f"HIT {hit_id} is already expired", state="expired")
    call(client, "update_expiration_for_hit", HITId=hit_id, ExpireAt=_PAST)
    row.expired_at = datetime.now(UTC)
    session.flush()
    return row


def add_assignments(session: Session, client: MTurkClient, hit_id: str, count: int,
                    allow_large_hits: bool = False) -> CrowdHit:
    """Raise the HIT's MaxAssignments by ``count``; the token makes a retry add nothing."""
    row = get_hit_or_raise(session, hit_id)
    check_assignments(row.max_assignments + count, allow_large_hits)
    token = f"dxadd-{hit_id[:40]}-{row.max_assignments}"
    call_naming(client, "create_additional_assignments_for_hit",
                {"NumberOfAdditionalAssignments": "count"}, HITId=hit_id,
                NumberOfAdditionalAssignments=count, UniqueRequestToken=token)
    row.max_assignments += count
    session.flush()
    return row


def _worker_action(session: Session, worker_id: str, kind: str, target: str
                   ) -> CrowdWorkerAction | None:
    return session.scalar(select(CrowdWorkerAction).where(
        CrowdWorkerAction.worker_id == worker_id, CrowdWorkerAction.kind == kind,
        CrowdWorkerAction.target == target))


def grant_qualification(session: Session, client: MTurkClient, worker_id: str,
                        type_id: str | None, value: int = 1, notify: bool = False) -> str:
    """Grant a qualification (unset: our "passed training" type); its type id."""
    with session.no_autoflush:  # our rows are written after the marketplace calls
        type_id = type_id or training_qualification(session, client)
        if _worker_action(session, worker_id, "qualification", type_id) is not None:
            raise Conflict(f"worker {worker_id} already holds qualification {type_id}",
                           state="granted")
        call_naming(client, "associate_qualification_with_worker",
                    {"IntegerValue": "value", "SendNotification": "notify"},
                    QualificationTypeId=type_id, WorkerId=worker_id, IntegerValue=value,
                    SendNotification=notify)
    session.add(CrowdWorkerAction(worker_id=worker_id, kind="qualification", target=type_id,
                                  value=value))
    session.flush()
    return type_id


def revoke_qualification(session: Session, client: MTurkClient, worker_id: str,
                         type_id: str | None, reason: str | None = None) -> str:
    with session.no_autoflush:
        type_id = type_id or training_qualification(session, client)
        row = _worker_action(session, worker_id, "qualification", type_id)
        if row is None:
            raise Conflict(f"worker {worker_id} does not hold qualification {type_id}",
                           state="not_granted")
        params = {"WorkerId": worker_id, "QualificationTypeId": type_id}
        if reason:
            params["Reason"] = reason
        call(client, "disassociate_qualification_from_worker", **params)
    session.delete(row)
    session.flush()
    return type_id


def block_worker(session: Session, client: MTurkClient, worker_id: str, reason: str) -> None:
    if _worker_action(session, worker_id, "block", "") is not None:
        raise Conflict(f"worker {worker_id} is already blocked", state="blocked")
    call(client, "create_worker_block", WorkerId=worker_id, Reason=reason)
    session.add(CrowdWorkerAction(worker_id=worker_id, kind="block", target="", reason=reason))
    session.flush()


def unblock_worker(session: Session, client: MTurkClient, worker_id: str,
                   reason: str | None = None) -> None:
    """Lift our block of ``worker_id`` (DeleteWorkerBlock); not blocked is a Conflict."""
    row = _worker_action(session, worker_id, "block", "")
    if row is None:
        raise Conflict(f"worker {worker_id} is not blocked", state="not_blocked")
    params = {"WorkerId": worker_id}
    if reason:
        params["Reason"] = reason
    call(client, "delete_worker_block", **params)
    session.delete(row)
    session.flush()


def notify_workers(client: MTurkClient, worker_ids: list[str], subject: str,
                   message: str) -> list[dict]:
    """Send a message; the marketplace's per-worker failures (empty when all went out)."""
    reply = call_naming(client, "notify_workers", {"MessageText": "message"},
                        WorkerIds=worker_ids, Subject=subject, MessageText=message)
    return list(reply.get("NotifyWorkersFailureStatuses", []))
