"""Collecting submissions from the marketplace and checking them against our assignments.

A submission counts only when the requester API's record (ListAssignmentsForHIT) names the same
HIT and worker as the annotation assignment our page opened for that AssignmentId: a worker
cannot claim someone else's work by replaying an id.
"""

from __future__ import annotations

from sqlalchemy import select, update
from sqlalchemy.dialects.postgresql import insert as pg_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment
from backend.crowd.client import MTurkClient, paginate
from backend.crowd.models import CrowdHit, CrowdSubmission
from backend.crowd.schemas import SyncResult
from backend.db import utcnow
from backend.errors import Conflict

COLLECTED_STATUSES = ["Submitted", "Approved", "Rejected"]


def verified_submission(session: Session, assignment: Assignment) -> CrowdSubmission:
    """The checked submission of ``assignment``, or a Conflict saying to sync first."""
    row = session.scalar(select(CrowdSubmission).where(
        CrowdSubmission.assignment_id == assignment.id))
    if row is None:
        raise Conflict(f"assignment {assignment.id} has no submission confirmed by the "
                       "marketplace yet; run `dexlabel crowd sync` first")
    return row


def _accept(session: Session, ours: Assignment, record: dict) -> bool:
    """Record a matching submission; False when already recorded (also when a concurrent unit
    of work, a confirm job beside a `crowd sync`, records it first: the insert then waits for
    that one and does nothing)."""
    insert = pg_insert if session.get_bind().dialect.name == "postgresql" else sqlite_insert
    made = session.execute(
        insert(CrowdSubmission).values(assignment_id=ours.id, hit_id=record["HITId"],
                                       worker_id=record["WorkerId"],
                                       market_status=record["AssignmentStatus"],
                                       created_at=utcnow())
        .on_conflict_do_nothing(index_elements=["assignment_id"])
        .returning(CrowdSubmission.id)).scalar_one_or_none()
    if made is not None:
        return True
    session.execute(update(CrowdSubmission)
                    .where(CrowdSubmission.assignment_id == ours.id)
                    .values(market_status=record["AssignmentStatus"])
                    .execution_options(synchronize_session=False))
    return False


def accept_record(session: Session, record: dict) -> tuple[str, Assignment | None]:
    """Check one requester-API assignment record against ours and record it.

    Returns the outcome ("accepted", "already_accepted", "mismatched" or "unknown") and our
    assignment when the record matched it.
    """
    ours = session.scalar(select(Assignment).where(
        Assignment.external_id == record["AssignmentId"]))
    if ours is None:
        return "unknown", None
    if ours.hit_id != record["HITId"] or ours.worker_id != record["WorkerId"]:
        return "mismatched", None
    return ("accepted" if _accept(session, ours, record) else "already_accepted"), ours


def _records(client: MTurkClient, hit_ids: list[str]) -> list[dict]:
    return [record for hit_id in hit_ids
            for record in paginate(client, "list_assignments_for_hit", "Assignments",
                                   HITId=hit_id, AssignmentStatuses=COLLECTED_STATUSES)]


def sync(session: Session, client: MTurkClient, hit_ids: list[str] | None = None) -> SyncResult:
    """Collect the submitted, approved and rejected assignments of our published HITs.

    All marketplace pages are read before anything is written (no transaction held open
    across HTTP calls).
    """
    if hit_ids is None:
        hit_ids = list(session.scalars(select(CrowdHit.hit_id).where(
            CrowdHit.hit_id.is_not(None)).order_by(CrowdHit.id)))
    result = SyncResult(hits=len(hit_ids), accepted=0, already_accepted=0, mismatched=[],
                        unknown=[])
    for record in _records(client, hit_ids):
        outcome, ours = accept_record(session, record)
        if outcome in ("unknown", "mismatched"):
            getattr(result, outcome).append(record["AssignmentId"])
        else:
            setattr(result, outcome, getattr(result, outcome) + 1)
        if outcome == "accepted" and ours is not None:
            result.accepted_ids.append(ours.id)
    session.flush()
    return result
