"""The admin page's view of the crowd (``/api/crowd``, admins only): each task's units of work
with their places, holders and states; a unit's assignments with the portal account behind
each worker; closing work left "working"; the team's portal accounts.

A unit of work is a published HIT (``crowd_hits``), whichever provider holds it: its
``provider`` column (migration 0021 made every unit published before providers were chosen
"mturk"). The providers offered are the registry's (``backend.crowd.provider.PROVIDERS``).
Extending, expiring and adding places stay the crowd router's
(POST /api/crowd/hits/{hit_id}/...): this module only reads, and closes our own records.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any

from fastapi import APIRouter, Query
from pydantic import BaseModel
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from backend.accounts.deps import CurrentAdmin
from backend.accounts.models import PortalAccount
from backend.annotation.models import Assignment, Task
from backend.captures.models import Camera
from backend.config import get_settings
from backend.crowd import pricing
from backend.crowd.models import CrowdHit
from backend.crowd.provider import PROVIDERS, ProviderName
from backend.db import SessionDep
from backend.errors import Conflict, NotFound
from backend.validation import Id, Key, Offset, QueryId, QueryKey

router = APIRouter(prefix="/api/crowd", tags=["crowd"])

# Our status of work an admin closed: it holds no place, and its saved labels stay.
CLOSED = "closed"
Limit = Annotated[int, Query(ge=1, le=5000)]


class ProvidersRead(BaseModel):
    """The providers a task can be published to, and the one a publish uses unless told."""

    default: ProviderName
    choices: list[ProviderName]


class UnitRead(BaseModel):
    """One unit of work. places: how many workers it takes; decided: approved or rejected;
    holders: our assignments of it still being worked on; submitted: awaiting a decision."""

    hit_id: str
    task_id: int
    sequence_id: int
    target_key: str
    serial: str
    round: int
    provider: str
    reward: str
    places: int
    decided: int
    holders: int
    submitted: int
    state: str  # "open" or "expired"
    expired_at: datetime | None
    published_at: datetime
    # Why it was published under the adaptive policy (backend.crowd.adaptive); None under
    # every view.
    reason: str | None = None


class UnitAssignmentRead(BaseModel):
    """One of our assignments of a unit, with the portal account of its worker (if any)."""

    assignment_id: int
    external_id: str
    worker_id: str
    account_email: str | None
    status: str
    started_at: datetime
    saved_at: datetime | None
    submitted_at: datetime | None
    working_time_s: float


class TeamAccountRead(BaseModel):
    """A portal account: the team member's email and the worker id their work carries."""

    id: int
    email: str
    worker_id: str
    active: bool
    created_at: datetime
    approved: int
    rejected: int


def _status_counts(session: Session, column: Any, keys: list[Any]) -> dict[Any, dict[str, int]]:
    """Our assignments per ``column`` value (a HIT or worker id) and status."""
    counts: dict[Any, dict[str, int]] = {key: {} for key in keys}
    if keys:
        for key, status, n in session.execute(
                select(column, Assignment.status, func.count()).where(column.in_(keys))
                .group_by(column, Assignment.status)):
            counts[key][status] = n
    return counts


def list_units(session: Session, sequence_id: int | None, task_id: int | None,
               offset: int, limit: int) -> list[UnitRead]:
    """Published units, newest task first, each round of a task in order."""
    stmt = (select(CrowdHit, Task.sequence_id, Task.target_key, Camera.serial)
            .join(Task, Task.id == CrowdHit.task_id).join(Camera, Camera.id == Task.camera_id)
            .where(CrowdHit.hit_id.is_not(None)))
    if sequence_id is not None:
        stmt = stmt.where(Task.sequence_id == sequence_id)
    if task_id is not None:
        stmt = stmt.where(CrowdHit.task_id == task_id)
    rows = session.execute(stmt.order_by(CrowdHit.task_id.desc(), CrowdHit.round)
                           .offset(offset).limit(limit)).all()
    counts = _status_counts(session, Assignment.hit_id, [hit.hit_id for hit, *_ in rows])
    return [UnitRead(
        hit_id=str(hit.hit_id), task_id=hit.task_id, sequence_id=sequence, target_key=target,
        serial=serial, round=hit.round, provider=hit.provider,
        reward=pricing.cents_to_dollars(hit.reward_cents), places=hit.max_assignments,
        decided=hit.decided, holders=counts[hit.hit_id].get("working", 0),
        submitted=counts[hit.hit_id].get("submitted", 0),
        state="open" if hit.expired_at is None else "expired", expired_at=hit.expired_at,
        published_at=hit.created_at, reason=hit.reason)
        for hit, sequence, target, serial in rows]


def _emails(session: Session, worker_ids: set[str]) -> dict[str, str]:
    if not worker_ids:
        return {}
    rows = session.execute(select(PortalAccount.worker_id, PortalAccount.email)
                           .where(PortalAccount.worker_id.in_(worker_ids))).all()
    return {row.worker_id: row.email for row in rows}


def _assignment_read(assignment: Assignment, emails: dict[str, str]) -> UnitAssignmentRead:
    return UnitAssignmentRead(
        assignment_id=assignment.id, external_id=assignment.external_id,
        worker_id=assignment.worker_id, account_email=emails.get(assignment.worker_id),
        status=assignment.status, started_at=assignment.created_at,
        saved_at=assignment.saved_at, submitted_at=assignment.submitted_at,
        working_time_s=assignment.working_time_s)


def unit_assignments(session: Session, hit_id: str) -> list[UnitAssignmentRead]:
    """Our assignments of one unit, oldest first."""
    if session.scalar(select(CrowdHit.id).where(CrowdHit.hit_id == hit_id)) is None:
        raise NotFound(f"no published unit {hit_id}")
    found = list(session.scalars(select(Assignment).where(Assignment.hit_id == hit_id)
                                 .order_by(Assignment.id)))
    emails = _emails(session, {a.worker_id for a in found})
    return [_assignment_read(a, emails) for a in found]


def close_assignment(session: Session, assignment_id: int) -> UnitAssignmentRead:
    """Close work still "working" (a direct link left open, or work its worker walked away
    from): it no longer holds a place of its unit and can no longer be saved or submitted.
    Its saved labels stay as they are; the provider is not told (its own record of the
    assignment expires or is returned there).

    Raises:
        NotFound: no such assignment.
        Conflict: the work is not "working" (submitted, decided or closed already).
    """
    assignment = session.get(Assignment, assignment_id, with_for_update=True)
    if assignment is None:
        raise NotFound(f"no assignment {assignment_id}")
    if assignment.status != "working":
        raise Conflict(f"assignment {assignment_id} is {assignment.status}: only work still "
                       "being done can be closed", status=assignment.status)
    assignment.status = CLOSED
    session.flush()
    return _assignment_read(assignment, _emails(session, {assignment.worker_id}))


def team_accounts(session: Session, worker_id: str | None, offset: int,
                  limit: int) -> list[TeamAccountRead]:
    """Portal accounts, oldest first, with their approved and rejected work here."""
    stmt = select(PortalAccount).order_by(PortalAccount.id).offset(offset).limit(limit)
    if worker_id is not None:
        stmt = stmt.where(PortalAccount.worker_id == worker_id)
    accounts = list(session.scalars(stmt))
    counts = _status_counts(session, Assignment.worker_id, [a.worker_id for a in accounts])
    return [TeamAccountRead(
        id=a.id, email=a.email, worker_id=a.worker_id, active=a.active, created_at=a.created_at,
        approved=counts[a.worker_id].get("approved", 0),
        rejected=counts[a.worker_id].get("rejected", 0)) for a in accounts]


@router.get("/providers", response_model=ProvidersRead)
def providers(_: CurrentAdmin) -> ProvidersRead:
    """What the publish form offers, its default the setting ``DEXLABEL_CROWD_PROVIDER``."""
    return ProvidersRead(default=get_settings().crowd_provider, choices=list(PROVIDERS))


@router.get("/units", response_model=list[UnitRead])
def units(session: SessionDep, _: CurrentAdmin, sequence_id: QueryId = None,
          task_id: QueryId = None, offset: Offset = 0, limit: Limit = 500) -> list[UnitRead]:
    """Published units of work, of one sequence or task when asked."""
    return list_units(session, sequence_id, task_id, offset, limit)


@router.get("/units/{hit_id}/assignments", response_model=list[UnitAssignmentRead])
def assignments_of_unit(hit_id: Key, session: SessionDep,
                        _: CurrentAdmin) -> list[UnitAssignmentRead]:
    return unit_assignments(session, hit_id)


@router.post("/assignments/{assignment_id}/close", response_model=UnitAssignmentRead)
def close(assignment_id: Id, session: SessionDep, _: CurrentAdmin) -> UnitAssignmentRead:
    """Close work left "working": its place is free again, its saved labels are kept."""
    return close_assignment(session, assignment_id)


@router.get("/team", response_model=list[TeamAccountRead])
def team(session: SessionDep, _: CurrentAdmin, worker_id: QueryKey = None, offset: Offset = 0,
         limit: Limit = 500) -> list[TeamAccountRead]:
    """The team's portal accounts (one worker's, when ``worker_id`` is given)."""
    return team_accounts(session, worker_id, offset, limit)
