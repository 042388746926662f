"""The worker side of the marketplace: find HITs, accept, submit, return.

These functions serve the worker portal and the ``/mturk/externalSubmit`` form post. Their
errors are ordinary product errors (rendered as ``{"error", "detail"}`` or as a page), not
MTurk wire errors: workers never speak the requester protocol.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy import func, select
from sqlalchemy.orm import Session, selectinload

from backend.errors import Conflict, DexlabelError, Forbidden, NotFound
from backend.market import lifecycle
from backend.market.blocks import blocked_requesters
from backend.market.context import new_id
from backend.market.lifecycle import OCCUPYING, HitState
from backend.market.models import Hit, MarketAssignment, Worker
from backend.market.questions import answers_xml
from backend.market.requirements import WorkerProfile, allowed_actions, worker_profile

WORKER_ID_RE = re.compile(r"A[A-Z0-9]{1,63}")  # CustomerId in the service model
SUBMIT_ID_FIELD = "assignmentId"


@dataclass(frozen=True)
class WorkerHit:
    """A HIT as one worker sees it."""

    hit: Hit
    state: HitState
    can_discover: bool
    can_preview: bool
    can_accept: bool


def get_or_create_worker(
    session: Session, worker_id: str, now: datetime, country: str | None = None,
    subdivision: str | None = None,
) -> Worker:
    if WORKER_ID_RE.fullmatch(worker_id) is None:
        raise DexlabelError(f"worker id {worker_id!r} must be 'A' and then A-Z or 0-9")
    worker = session.scalars(select(Worker).where(Worker.worker_id == worker_id)).one_or_none()
    if worker is None:
        worker = Worker(worker_id=worker_id, created_at=now)
        session.add(worker)
    if country is not None:
        worker.locale_country, worker.locale_subdivision = country, subdivision
    session.flush()
    return worker


def _view(hit: Hit, state: HitState, profile: WorkerProfile) -> WorkerHit:
    actions = allowed_actions(profile, hit.hit_type.qualification_requirements)
    return WorkerHit(hit, state, "Discover" in actions, "Preview" in actions,
                     "Accept" in actions and state.status == "Assignable")


def list_available_hits(session: Session, worker_id: str, now: datetime) -> list[WorkerHit]:
    """Assignable HITs the worker may discover and has not worked on, oldest first."""
    blocked = blocked_requesters(session, worker_id)
    stmt = (select(Hit).where(Hit.disposed_at.is_(None), Hit.expiration > now)
            .options(selectinload(Hit.assignments), selectinload(Hit.hit_type)).order_by(Hit.id))
    profile = worker_profile(session, worker_id)
    found = []
    for hit in session.scalars(stmt):
        if hit.requester in blocked or _occupied_by(hit, worker_id):
            continue
        view = _view(hit, lifecycle.refresh_hit(session, hit, now), profile)
        if view.state.status == "Assignable" and view.can_discover:
            found.append(view)
    return found


def _occupied_by(hit: Hit, worker_id: str) -> bool:
    return any(a.worker_id == worker_id and a.status in OCCUPYING for a in hit.assignments)


def _load_hit(session: Session, hit_id: str, lock: bool = False) -> Hit:
    stmt = (select(Hit).where(Hit.hit_id == hit_id)
            .options(selectinload(Hit.assignments), selectinload(Hit.hit_type)))
    if lock:
        stmt = stmt.with_for_update()
    hit = session.scalars(stmt).one_or_none()
    if hit is None or hit.disposed_at is not None:
        raise NotFound(f"HIT {hit_id} does not exist")
    return hit


def preview(session: Session, worker_id: str, hit_id: str, now: datetime) -> WorkerHit:
    """One HIT for the worker's preview page."""
    hit = _load_hit(session, hit_id)
    state = lifecycle.refresh_hit(session, hit, now)
    return _view(hit, state, worker_profile(session, worker_id))


def accept(session: Session, worker_id: str, hit_id: str, now: datetime) -> MarketAssignment:
    """Give the worker one of the HIT's free assignments, due by AssignmentDurationInSeconds."""
    get_or_create_worker(session, worker_id, now)
    hit = _load_hit(session, hit_id, lock=True)  # one slot, one worker: lock the HIT row
    if hit.requester in blocked_requesters(session, worker_id):
        raise Forbidden("the requester of this HIT does not accept work from you")
    state = lifecycle.refresh_hit(session, hit, now)
    if _occupied_by(hit, worker_id):
        raise Conflict(f"you already work on HIT {hit_id}")
    if state.status != "Assignable":
        raise Conflict(f"HIT {hit_id} has no assignment left to accept ({state.status})")
    profile = worker_profile(session, worker_id)
    if "Accept" not in allowed_actions(profile, hit.hit_type.qualification_requirements):
        raise Forbidden(f"you do not meet the qualification requirements of HIT {hit_id}")
    assignment = MarketAssignment(
        assignment_id=new_id("3"), hit=hit, worker_id=worker_id, status="Accepted",
        accept_time=now, deadline=now + timedelta(seconds=hit.hit_type.assignment_duration_s))
    session.add(assignment)
    session.flush()
    _refuse_overbooking(session, hit)
    lifecycle.refresh_hit(session, hit, now)
    return assignment


def _refuse_overbooking(session: Session, hit: Hit) -> None:
    # The last guard on capacity, counted once this transaction holds the write: PostgreSQL
    # serialises accepts on the locked HIT row, SQLite on its single writer.
    taken = session.scalar(select(func.count()).select_from(MarketAssignment).where(
        MarketAssignment.hit_pk == hit.id, MarketAssignment.status.in_(OCCUPYING)))
    if (taken or 0) > hit.max_assignments:
        raise Conflict(f"HIT {hit.hit_id} has no assignment left to accept")


def _load_assignment(session: Session, assignment_id: str, now: datetime) -> MarketAssignment:
    stmt = (select(MarketAssignment).where(MarketAssignment.assignment_id == assignment_id)
            .options(selectinload(MarketAssignment.hit).selectinload(Hit.assignments),
                     selectinload(MarketAssignment.hit).selectinload(Hit.hit_type)))
    assignment = session.scalars(stmt).one_or_none()
    if assignment is None:
        raise NotFound(f"assignment {assignment_id} does not exist")
    lifecycle.refresh_hit(session, assignment.hit, now)
    return assignment


_NOT_OPEN = {
    "Submitted": "was already submitted",
    "Approved": "was already submitted and approved",
    "Rejected": "was already submitted and rejected",
    "Returned": "was returned",
    "Abandoned": "ran past its deadline and was released",
}


def _require_accepted(assignment: MarketAssignment) -> None:
    if assignment.status != "Accepted":
        raise Conflict(f"assignment {assignment.assignment_id} "
                       f"{_NOT_OPEN.get(assignment.status, 'is not open')}")


def submit_external(
    session: Session, assignment_id: str, fields: list[tuple[str, str]], now: datetime
) -> MarketAssignment:
    """Record the form an ExternalQuestion page posted: one Answer per field but assignmentId."""
    assignment = _load_assignment(session, assignment_id, now)
    _require_accepted(assignment)
    answers = [(name, value) for name, value in fields if name != SUBMIT_ID_FIELD]
    assignment.answer = answers_xml(answers)
    assignment.status = "Submitted"
    assignment.submit_time = now
    assignment.auto_approval_time = now + timedelta(
        seconds=assignment.hit.hit_type.auto_approval_delay_s)
    lifecycle.refresh_hit(session, assignment.hit, now)
    return assignment


def return_assignment(
    session: Session, worker_id: str, assignment_id: str, now: datetime
) -> MarketAssignment:
    """The worker gives the assignment back; its slot is free again while the HIT is open."""
    assignment = _load_assignment(session, assignment_id, now)
    if assignment.worker_id != worker_id:
        raise NotFound(f"assignment {assignment_id} does not exist")
    _require_accepted(assignment)
    assignment.status = "Returned"
    lifecycle.refresh_hit(session, assignment.hit, now)
    return assignment
