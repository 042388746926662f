"""HTTP endpoints of the worker portal (``/api/portal``); the page is frontend/market/."""

from __future__ import annotations

from datetime import timedelta

from fastapi import APIRouter, Query, Response
from sqlalchemy.orm import Session

from backend.accounts import service as account_service
from backend.accounts.deps import CurrentAdmin, CurrentWorker, current_worker
from backend.accounts.models import PortalAccount
from backend.accounts.routes import add_sign_in_routes
from backend.accounts.service import WORKER
from backend.config import get_settings
from backend.crowd.titles import TaskFacts
from backend.db import SessionDep
from backend.errors import Unauthorized
from backend.market import clock
from backend.market.models import MarketAssignment
from backend.market.money import format_amount
from backend.market.workers import WorkerHit
from backend.portal import accounts, service, tasks
from backend.portal.schemas import (
    AccountCreate,
    AccountRead,
    AssignmentRead,
    AssignmentsRead,
    EarningsRead,
    HitMineRead,
    HitPreview,
    HitRead,
    HitTaskRead,
    InviteCreate,
    InviteRead,
    Register,
    WorkerTokenRead,
)
from backend.validation import Key

router = APIRouter(prefix="/api/portal", tags=["worker portal"])


def _token_read(account_id: int, token_epoch: int, worker_id: str | None) -> WorkerTokenRead:
    assert worker_id is not None  # every portal account has one
    token = account_service.account_token(WORKER, account_id, token_epoch, worker_id=worker_id)
    return WorkerTokenRead(access_token=token, expires_in=WORKER.ttl_s, worker_id=worker_id)


def _account_read(account: PortalAccount) -> AccountRead:
    return AccountRead(id=account.id, email=account.email, worker_id=account.worker_id)


def _hit_reads(session: Session, worker_id: str,
               listed: list[tuple[WorkerHit, MarketAssignment | None]]) -> list[HitRead]:
    """Rows of a HIT list: each HIT with what it is about, whether it is assigned to this
    worker alone, and the worker's own assignment on it (if any)."""
    hits = [view.hit for view, _ in listed]
    facts = tasks.hit_facts(session, hits)
    assigned = service.assigned_to(session, worker_id, hits)
    return [_hit_read(view, facts[view.hit.hit_id], mine, view.hit.hit_id in assigned)
            for view, mine in listed]


def _hit_read(view: WorkerHit, facts: TaskFacts | None,
              mine: MarketAssignment | None = None, assigned: bool = False) -> HitRead:
    hit_type = view.hit.hit_type
    task = None if facts is None else HitTaskRead(
        kind=facts.kind, target=facts.target, view=facts.serial, view_name=facts.view_name,
        frames=facts.num_frames)
    return HitRead(hit_id=view.hit.hit_id, title=hit_type.title, description=hit_type.description,
                   keywords=hit_type.keywords, reward=format_amount(hit_type.reward_cents),
                   assignment_duration_s=hit_type.assignment_duration_s,
                   available=view.state.available, expiration=view.hit.expiration,
                   can_accept=view.can_accept and mine is None, task=task,
                   assigned_to_me=assigned,
                   thumbnail_url=None if facts is None else tasks.thumbnail_url(view.hit.hit_id),
                   mine=None if mine is None else HitMineRead(
                       assignment_id=mine.assignment_id, status=mine.status))


def _assignment_read(assignment: MarketAssignment, bonus_cents: int) -> AssignmentRead:
    hit = assignment.hit
    open_ = assignment.status == "Accepted"
    submit_to = get_settings().public_url
    return AssignmentRead(
        assignment_id=assignment.assignment_id, hit_id=hit.hit_id, title=hit.hit_type.title,
        status=assignment.status, reward=format_amount(hit.hit_type.reward_cents),
        bonus=format_amount(bonus_cents), accept_time=assignment.accept_time,
        deadline=assignment.deadline, submit_time=assignment.submit_time,
        feedback=assignment.requester_feedback,
        work_url=service.work_url(assignment, submit_to) if open_ else None,
        frame_height=service.frame_height(hit))


@router.post("/workers", response_model=AccountRead)
def create_worker(body: AccountCreate, session: SessionDep, _: CurrentAdmin) -> AccountRead:
    """An admin creates a worker account directly."""
    return _account_read(accounts.create_account(session, body.email, body.password, clock.now()))


@router.post("/invites", response_model=InviteRead)
def create_invite(body: InviteCreate, session: SessionDep, admin: CurrentAdmin) -> InviteRead:
    """A one-time registration link; the invite token is shown only in this reply."""
    token, invite = accounts.create_invite(session, admin, timedelta(hours=body.ttl_hours),
                                           clock.now())
    # In the fragment, which the browser never sends: the token stays out of access logs,
    # proxies and Referer headers.
    url = f"{get_settings().public_url.rstrip('/')}/market/#invite={token}"
    return InviteRead(invite=token, url=url, expires_at=invite.expires_at)


@router.post("/register", response_model=AccountRead)
def register(body: Register, session: SessionDep) -> AccountRead:
    return _account_read(accounts.register(session, body.invite, body.email, body.password,
                                           clock.now()))


add_sign_in_routes(router, WORKER, login_path="/login", holder="worker account",
                   current_account=current_worker, token_model=WorkerTokenRead,
                   token_reply=_token_read)


@router.get("/me", response_model=AccountRead)
def me(worker: CurrentWorker) -> AccountRead:
    return _account_read(worker)


@router.get("/hits", response_model=list[HitRead])
def list_hits(
    session: SessionDep, worker: CurrentWorker,
    mine: bool = Query(False, description="also list the HITs this worker holds (first, "
                                          "marked Accepted) or submitted (last, marked Submitted)"),
) -> list[HitRead]:
    """Assignable HITs this worker qualifies for and has not worked on; each names its task
    (target, view, frames) and links a thumbnail of the view's first frame."""
    if mine:
        worklist = service.worklist(session, worker.worker_id, clock.now())
        return _hit_reads(session, worker.worker_id,
                          [(listed.view, listed.mine) for listed in worklist])
    return _hit_reads(session, worker.worker_id,
                      [(v, None) for v in service.list_hits(session, worker.worker_id, clock.now())
                       if v.can_accept])


@router.get("/hits/{hit_id}/thumbnail.jpg", response_class=Response,
            responses={200: {"content": {"image/jpeg": {}}}})
def hit_thumbnail(
    hit_id: Key, session: SessionDep,
    token: str | None = Query(default=None, min_length=1, max_length=4096,
                              description="the thumbnail token of this HIT, from the HIT list"),
) -> Response:
    """The first frame of the HIT's view, 160 px wide. Read with the token from the HIT list
    (an <img> sends no bearer header); that token opens this one picture and nothing else.
    Without a token: 401, like every route that needs one."""
    if token is None:
        raise Unauthorized("a thumbnail needs its token (?token= from the HIT list)")
    tasks.check_thumbnail_token(token, hit_id)
    return Response(tasks.thumbnail_jpeg(session, hit_id), media_type="image/jpeg",
                    headers={"Cache-Control": f"private, max-age={tasks.THUMBNAIL_TTL_S}"})


@router.get("/hits/{hit_id}", response_model=HitPreview)
def preview_hit(hit_id: Key, session: SessionDep, worker: CurrentWorker) -> HitPreview:
    view = service.preview(session, worker.worker_id, hit_id, clock.now())
    return HitPreview(**_hit_reads(session, worker.worker_id, [(view, None)])[0].model_dump(),
                      preview_url=service.preview_url(view),
                      frame_height=service.frame_height(view.hit))


@router.post("/hits/{hit_id}/accept", response_model=AssignmentRead)
def accept_hit(hit_id: Key, session: SessionDep, worker: CurrentWorker) -> AssignmentRead:
    """Takes one assignment; its ``work_url`` is the page to frame."""
    return _assignment_read(service.accept(session, worker.worker_id, hit_id, clock.now()), 0)


@router.post("/assignments/{assignment_id}/return", response_model=AssignmentRead)
def return_assignment(assignment_id: Key, session: SessionDep,
                      worker: CurrentWorker) -> AssignmentRead:
    assignment = service.return_assignment(session, worker.worker_id, assignment_id, clock.now())
    return _assignment_read(assignment, 0)


@router.get("/assignments", response_model=AssignmentsRead)
def my_assignments(session: SessionDep, worker: CurrentWorker) -> AssignmentsRead:
    """Every assignment of this worker with its status and feedback, and the money earned."""
    found = service.my_assignments(session, worker.worker_id, clock.now())
    bonuses = service.bonuses_by_assignment(session, worker.worker_id)
    money = service.earnings(found, bonuses)
    return AssignmentsRead(
        assignments=[_assignment_read(a, bonuses.get(a.id, 0)) for a in found],
        earnings=EarningsRead(paid=format_amount(money.paid_cents),
                              pending=format_amount(money.pending_cents),
                              bonuses=format_amount(money.bonus_cents)))


@router.get("/assignments/{assignment_id}", response_model=AssignmentRead)
def get_assignment(assignment_id: Key, session: SessionDep,
                   worker: CurrentWorker) -> AssignmentRead:
    assignment = service.get_assignment(session, worker.worker_id, assignment_id, clock.now())
    bonus = service.bonuses_by_assignment(session, worker.worker_id).get(assignment.id, 0)
    return _assignment_read(assignment, bonus)
