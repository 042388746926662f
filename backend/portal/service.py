"""What a signed-in worker does in the portal: find HITs, preview, accept, return, and look
back at their assignments, feedback and earnings.

The marketplace rules live in ``backend.market.workers``; this module adds what the portal page
needs on top: the URL of the annotation page exactly as MTurk frames it, and money summed per
worker. Amounts are integer cents.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections import defaultdict
from dataclasses import dataclass
from datetime import datetime
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

from sqlalchemy import select
from sqlalchemy.orm import Session, selectinload
from sqlalchemy.orm.exc import StaleDataError

from backend.config import TEAM_MARKET_ACCESS_KEY
from backend.crowd.providers.team import ASSIGNEE_PREFIX
from backend.errors import Busy, Forbidden, NotFound
from backend.market import lifecycle, workers
from backend.market.models import Bonus, Hit, MarketAssignment, QualificationType
from backend.market.questions import EXTERNAL_QUESTION_NS, external_url
from backend.market.workers import WorkerHit

PREVIEW_ASSIGNMENT_ID = "ASSIGNMENT_ID_NOT_AVAILABLE"
DEFAULT_FRAME_HEIGHT = 800
LISTING_ATTEMPTS = 3


@dataclass(frozen=True)
class Earnings:
    paid_cents: int  # rewards of approved assignments plus every bonus
    pending_cents: int  # rewards of submitted assignments not yet reviewed
    bonus_cents: int


def frame_url(hit: Hit, params: dict[str, str]) -> str | None:
    """The HIT's ExternalURL with MTurk's query parameters added (None for other questions)."""
    url = external_url(hit.question)
    if url is None:
        return None
    parts = urlsplit(url)
    query = [(k, v) for k, v in parse_qsl(parts.query, keep_blank_values=True) if k not in params]
    return urlunsplit(parts._replace(query=urlencode([*query, *params.items()])))


def frame_height(hit: Hit) -> int:
    """FrameHeight of the ExternalQuestion in px; 0 asks MTurk to size the frame itself."""
    node = ET.fromstring(hit.question).find(f"{{{EXTERNAL_QUESTION_NS}}}FrameHeight")
    text = (node.text or "").strip() if node is not None else ""
    return int(text) if text.isdigit() else DEFAULT_FRAME_HEIGHT


def preview_url(view: WorkerHit) -> str | None:
    return frame_url(view.hit, {"assignmentId": PREVIEW_ASSIGNMENT_ID, "hitId": view.hit.hit_id})


def work_url(assignment: MarketAssignment, submit_to: str) -> str | None:
    """Where the accepted assignment is worked; the page posts its form to
    ``{turkSubmitTo}/mturk/externalSubmit``."""
    return frame_url(assignment.hit, {
        "assignmentId": assignment.assignment_id, "hitId": assignment.hit.hit_id,
        "workerId": assignment.worker_id, "turkSubmitTo": submit_to.rstrip("/")})


def list_hits(session: Session, worker_id: str, now: datetime) -> list[WorkerHit]:
    """The HITs the worker can take. Listing settles what the clock made due on each HIT it
    shows, a write that can lose to a concurrent one on the same HIT (another worker's accept,
    the requester's review); the listing then starts again from the winner's state.

    Raises:
        Busy: the HITs kept changing under the listing (503; asking again works).
    """
    for _ in range(LISTING_ATTEMPTS):
        try:
            return workers.list_available_hits(session, worker_id, now)
        except StaleDataError:
            session.rollback()
    raise Busy("the HITs changed while they were listed; please try again")


@dataclass(frozen=True)
class ListedHit:
    view: WorkerHit
    mine: MarketAssignment | None  # the worker's Accepted or Submitted assignment on it


def worklist(session: Session, worker_id: str, now: datetime) -> list[ListedHit]:
    """The worker's HIT list: the HITs they hold (Accepted, to continue) first, then those
    they can take, then those they submitted while the HIT is still up. Retried like
    ``list_hits``.

    Raises:
        Busy: the HITs kept changing under the listing (503; asking again works).
    """
    for _ in range(LISTING_ATTEMPTS):
        try:
            return _worklist(session, worker_id, now)
        except StaleDataError:
            session.rollback()
    raise Busy("the HITs changed while they were listed; please try again")


def _worklist(session: Session, worker_id: str, now: datetime) -> list[ListedHit]:
    available = [ListedHit(v, None) for v in workers.list_available_hits(session, worker_id, now)
                 if v.can_accept]
    held: list[ListedHit] = []
    submitted: list[ListedHit] = []
    for assignment in my_assignments(session, worker_id, now):
        hit = assignment.hit
        if assignment.status not in ("Accepted", "Submitted") or hit.disposed_at is not None:
            continue
        if assignment.status == "Submitted" and hit.expiration <= now:
            continue
        view = workers.preview(session, worker_id, hit.hit_id, now)
        (held if assignment.status == "Accepted" else submitted).append(
            ListedHit(view, assignment))
    return [*held, *available, *submitted]


def assigned_to(session: Session, worker_id: str, hits: list[Hit]) -> set[str]:
    """The ids of the team tasks among ``hits`` assigned to this worker alone: those that
    require the worker's own assignee qualification type (backend.crowd.providers.team)."""
    own = session.scalar(select(QualificationType.type_id).where(
        QualificationType.requester == TEAM_MARKET_ACCESS_KEY,
        QualificationType.name == ASSIGNEE_PREFIX + worker_id))
    if own is None:
        return set()
    return {hit.hit_id for hit in hits
            if any(req["QualificationTypeId"] == own
                   for req in hit.hit_type.qualification_requirements)}


def preview(session: Session, worker_id: str, hit_id: str, now: datetime) -> WorkerHit:
    view = workers.preview(session, worker_id, hit_id, now)
    if not view.can_discover:
        raise NotFound(f"HIT {hit_id} does not exist")
    if not view.can_preview:
        raise Forbidden(f"you do not meet the qualification requirements to preview HIT {hit_id}")
    return view


def accept(session: Session, worker_id: str, hit_id: str, now: datetime) -> MarketAssignment:
    return workers.accept(session, worker_id, hit_id, now)


def return_assignment(
    session: Session, worker_id: str, assignment_id: str, now: datetime
) -> MarketAssignment:
    return workers.return_assignment(session, worker_id, assignment_id, now)


def my_assignments(session: Session, worker_id: str, now: datetime) -> list[MarketAssignment]:
    """The worker's assignments, newest first, with the clock's transitions applied
    (abandoned past the deadline, auto-approved past AutoApprovalTime)."""
    hit_pks = set(session.scalars(
        select(MarketAssignment.hit_pk).where(MarketAssignment.worker_id == worker_id)))
    for hit in lifecycle.load_hits(session, hit_pks):
        lifecycle.refresh_hit(session, hit, now)
    stmt = (select(MarketAssignment).where(MarketAssignment.worker_id == worker_id)
            .options(selectinload(MarketAssignment.hit).selectinload(Hit.hit_type))
            .order_by(MarketAssignment.accept_time.desc(), MarketAssignment.id.desc()))
    return list(session.scalars(stmt))


def get_assignment(
    session: Session, worker_id: str, assignment_id: str, now: datetime
) -> MarketAssignment:
    for assignment in my_assignments(session, worker_id, now):
        if assignment.assignment_id == assignment_id:
            return assignment
    raise NotFound(f"assignment {assignment_id} does not exist")


def bonuses_by_assignment(session: Session, worker_id: str) -> dict[int, int]:
    """Bonus cents paid to the worker, per assignment primary key."""
    totals: dict[int, int] = defaultdict(int)
    for bonus in session.scalars(select(Bonus).where(Bonus.worker_id == worker_id)):
        totals[bonus.assignment_pk] += bonus.amount_cents
    return dict(totals)


def earnings(assignments: list[MarketAssignment], bonuses: dict[int, int]) -> Earnings:
    reward = {a.id: a.hit.hit_type.reward_cents for a in assignments}
    approved = sum(reward[a.id] for a in assignments if a.status == "Approved")
    pending = sum(reward[a.id] for a in assignments if a.status == "Submitted")
    bonus = sum(bonuses.values())
    return Earnings(paid_cents=approved + bonus, pending_cents=pending, bonus_cents=bonus)
