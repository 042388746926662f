"""Collecting submissions from the crowd providers and checking them against our assignments.

A submission counts only when the provider's record (MTurk: ListAssignmentsForHIT) names the
same unit and worker as the annotation assignment our page opened for that id: a worker cannot
claim someone else's work by replaying an id.
"""

from __future__ import annotations

from collections.abc import Iterator

from sqlalchemy import select, update
from sqlalchemy.dialects.postgresql import insert as pg_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment
from backend.config import get_settings
from backend.crowd.models import CrowdHit, CrowdSubmission
from backend.crowd.provider import COLLECTED, CrowdProvider, SubmissionRecord, SubmissionStatus
from backend.crowd.providers import get_provider, provider_of
from backend.crowd.schemas import SyncResult
from backend.db import utcnow
from backend.errors import Conflict

# A submission's status as crowd_submissions.market_status spells it (the words it has held
# since MTurk was the only crowd).
LEDGER_STATUS: dict[SubmissionStatus, str] = {
    "held": "Accepted", "submitted": "Submitted", "approved": "Approved",
    "rejected": "Rejected", "returned": "Returned"}
COLLECTED_STATUSES = [LEDGER_STATUS[status] for status in ("submitted", "approved", "rejected")]
assert {s for s, word in LEDGER_STATUS.items() if word in COLLECTED_STATUSES} == COLLECTED


def verified_submission(session: Session, assignment: Assignment) -> CrowdSubmission:
    """The checked submission of ``assignment``, or a Conflict saying to sync first."""
    row = session.scalar(select(CrowdSubmission).where(
        CrowdSubmission.assignment_id == assignment.id))
    if row is None:
        raise Conflict(f"assignment {assignment.id} has no submission confirmed by the "
                       "marketplace yet; run `dexlabel crowd sync` first")
    return row


def _accept(session: Session, ours: Assignment, record: SubmissionRecord) -> bool:
    """Record a matching submission; False when already recorded (also when a concurrent unit
    of work, a confirm job beside a `crowd sync`, records it first: the insert then waits for
    that one and does nothing)."""
    insert = pg_insert if session.get_bind().dialect.name == "postgresql" else sqlite_insert
    status = LEDGER_STATUS[record.status]
    made = session.execute(
        insert(CrowdSubmission).values(assignment_id=ours.id, hit_id=record.unit_id,
                                       worker_id=record.worker_id, market_status=status,
                                       provider=ours.provider, created_at=utcnow())
        .on_conflict_do_nothing(index_elements=["assignment_id"])
        .returning(CrowdSubmission.id)).scalar_one_or_none()
    if made is not None:
        return True
    session.execute(update(CrowdSubmission)
                    .where(CrowdSubmission.assignment_id == ours.id)
                    .values(market_status=status)
                    .execution_options(synchronize_session=False))
    return False


def accept_record(session: Session, record: SubmissionRecord) -> tuple[str, Assignment | None]:
    """Check one provider record of a submission against ours and record it.

    Returns the outcome ("accepted", "already_accepted", "mismatched" or "unknown") and our
    assignment when the record matched it.
    """
    ours = session.scalar(select(Assignment).where(
        Assignment.external_id == record.assignment_id))
    if ours is None:
        return "unknown", None
    if ours.hit_id != record.unit_id or ours.worker_id != record.worker_id:
        return "mismatched", None
    return ("accepted" if _accept(session, ours, record) else "already_accepted"), ours


def _records(session: Session, crowd: CrowdProvider | None,
             hit_ids: list[str] | None) -> tuple[int, list[SubmissionRecord]]:
    """The units to ask about (``hit_ids``, else every published one: of ``crowd``'s
    provider when one is given, else of every provider), and their collected submissions.
    Each unit is asked of ``crowd`` when given, else of its row's provider."""
    given = provider_of(crowd) if crowd is not None else None
    stmt = select(CrowdHit.hit_id, CrowdHit.provider).where(CrowdHit.hit_id.is_not(None))
    if hit_ids is not None:
        stmt = stmt.where(CrowdHit.hit_id.in_(hit_ids))
    elif given is not None:
        stmt = stmt.where(CrowdHit.provider == given.name)
    found: dict[str, str] = {h: name for h, name in session.execute(stmt.order_by(CrowdHit.id))
                             if h is not None}
    ids = list(found) if hit_ids is None else hit_ids
    by_provider: dict[str, list[str]] = {}
    for hit_id in ids:
        name = given.name if given else found.get(hit_id, get_settings().crowd_provider)
        by_provider.setdefault(name, []).append(hit_id)
    records: list[SubmissionRecord] = []
    for name, unit_ids in by_provider.items():
        provider = given if given is not None else get_provider(name)
        records.extend(_collected(provider, unit_ids))
    return len(ids), records


def _collected(provider: CrowdProvider, unit_ids: list[str]) -> Iterator[SubmissionRecord]:
    return (r for r in provider.submissions(unit_ids) if r.status in COLLECTED)


def sync(session: Session, crowd: CrowdProvider | None = None,
         hit_ids: list[str] | None = None) -> SyncResult:
    """Collect the submitted, approved and rejected work of our published units.

    All provider pages are read before anything is written (no transaction held open across
    HTTP calls).
    """
    units, records = _records(session, crowd, hit_ids)
    result = SyncResult(hits=units, accepted=0, already_accepted=0, mismatched=[],
                        unknown=[])
    for record in records:
        outcome, ours = accept_record(session, record)
        if outcome in ("unknown", "mismatched"):
            getattr(result, outcome).append(record.assignment_id)
        else:
            setattr(result, outcome, getattr(result, outcome) + 1)
        if outcome == "accepted" and ours is not None:
            result.accepted_ids.append(ours.id)
    session.flush()
    return result
