"""HTTP endpoints of the worker portal (``/api/portal``); the page is frontend/market/."""

from __future__ import annotations

from datetime import timedelta

from fastapi import APIRouter

from backend.accounts.deps import CurrentAdmin
from backend.config import get_settings
from backend.db import SessionDep
from backend.market import clock
from backend.market.models import MarketAssignment
from backend.market.money import format_amount
from backend.market.workers import WorkerHit
from backend.portal import accounts, service
from backend.portal.deps import PORTAL_TOKEN_TTL_S, CurrentWorker, portal_token
from backend.portal.models import PortalAccount
from backend.portal.schemas import (
    AccountCreate,
    AccountRead,
    AssignmentRead,
    AssignmentsRead,
    EarningsRead,
    HitPreview,
    HitRead,
    InviteCreate,
    InviteRead,
    Login,
    Register,
    TokenRead,
)

router = APIRouter(prefix="/api/portal", tags=["worker portal"])


def _account_read(account: PortalAccount) -> AccountRead:
    return AccountRead(id=account.id, email=account.email, worker_id=account.worker_id)


def _hit_read(view: WorkerHit) -> HitRead:
    hit_type = view.hit.hit_type
    return HitRead(hit_id=view.hit.hit_id, title=hit_type.title, description=hit_type.description,
                   keywords=hit_type.keywords, reward=format_amount(hit_type.reward_cents),
                   assignment_duration_s=hit_type.assignment_duration_s,
                   available=view.state.available, expiration=view.hit.expiration,
                   can_accept=view.can_accept)


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
    url = f"{get_settings().public_url.rstrip('/')}/market/?invite={token}"
    return InviteRead(invite=token, url=url, expires_at=invite.expires_at)


@router.post("/register", response_model=AccountRead)
def register(body: Register, session: SessionDep) -> AccountRead:
    return _account_read(accounts.register(session, body.invite, body.email, body.password,
                                           clock.now()))


@router.post("/login", response_model=TokenRead)
def login(body: Login, session: SessionDep) -> TokenRead:
    account = accounts.authenticate(session, body.email, body.password)
    return TokenRead(access_token=portal_token(account), expires_in=PORTAL_TOKEN_TTL_S,
                     worker_id=account.worker_id)


@router.get("/me", response_model=AccountRead)
def me(worker: CurrentWorker) -> AccountRead:
    return _account_read(worker)


@router.get("/hits", response_model=list[HitRead])
def list_hits(session: SessionDep, worker: CurrentWorker) -> list[HitRead]:
    """Assignable HITs this worker qualifies for and has not worked on."""
    return [_hit_read(v) for v in service.list_hits(session, worker.worker_id, clock.now())
            if v.can_accept]


@router.get("/hits/{hit_id}", response_model=HitPreview)
def preview_hit(hit_id: str, session: SessionDep, worker: CurrentWorker) -> HitPreview:
    view = service.preview(session, worker.worker_id, hit_id, clock.now())
    return HitPreview(**_hit_read(view).model_dump(), preview_url=service.preview_url(view),
                      frame_height=service.frame_height(view.hit))


@router.post("/hits/{hit_id}/accept", response_model=AssignmentRead)
def accept_hit(hit_id: str, session: SessionDep, worker: CurrentWorker) -> AssignmentRead:
    """Takes one assignment; its ``work_url`` is the page to frame."""
    return _assignment_read(service.accept(session, worker.worker_id, hit_id, clock.now()), 0)


@router.post("/assignments/{assignment_id}/return", response_model=AssignmentRead)
def return_assignment(assignment_id: str, session: SessionDep,
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
def get_assignment(assignment_id: str, session: SessionDep,
                   worker: CurrentWorker) -> AssignmentRead:
    assignment = service.get_assignment(session, worker.worker_id, assignment_id, clock.now())
    bonus = service.bonuses_by_assignment(session, worker.worker_id).get(assignment.id, 0)
    return _assignment_read(assignment, bonus)
