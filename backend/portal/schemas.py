"""Request and response shapes of the worker portal API. Money is a decimal string of USD
("0.50"), as MTurk writes it."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, Field

from backend.accounts.schemas import LoginRequest, TokenRead


class AccountCreate(LoginRequest):
    """A new worker account's email and password."""


class Register(AccountCreate):
    invite: str = Field(min_length=8, max_length=200)


class AccountRead(BaseModel):
    id: int
    email: str
    worker_id: str


class InviteCreate(BaseModel):
    ttl_hours: int = Field(default=7 * 24, ge=1, le=90 * 24)


class InviteRead(BaseModel):
    invite: str
    url: str
    expires_at: datetime


class WorkerTokenRead(TokenRead):
    worker_id: str


class HitTaskRead(BaseModel):
    """The dexlabel task a HIT is for."""

    kind: str  # "hand" | "object"
    target: str  # "right hand", "mustard bottle"
    view: str  # the camera serial
    view_name: str  # "camera 3 of 8": what the page shows
    frames: int


class HitMineRead(BaseModel):
    """This worker's assignment on the HIT: "Accepted" (still to finish) or "Submitted"."""

    assignment_id: str
    status: str


class HitRead(BaseModel):
    hit_id: str
    title: str
    task: HitTaskRead | None = None  # None: not a dexlabel task
    # The view's first frame, small; the URL works without a bearer header for 15 minutes.
    thumbnail_url: str | None = None
    mine: HitMineRead | None = None
    # A team task assigned to this worker alone (others are not offered it).
    assigned_to_me: bool = False
    description: str
    keywords: str | None
    reward: str
    assignment_duration_s: int
    available: int
    expiration: datetime
    can_accept: bool


class HitPreview(HitRead):
    preview_url: str | None
    frame_height: int


class AssignmentRead(BaseModel):
    assignment_id: str
    hit_id: str
    title: str
    status: str
    reward: str
    bonus: str
    accept_time: datetime
    deadline: datetime
    submit_time: datetime | None
    feedback: str | None
    work_url: str | None
    frame_height: int


class EarningsRead(BaseModel):
    paid: str
    pending: str
    bonuses: str


class AssignmentsRead(BaseModel):
    assignments: list[AssignmentRead]
    earnings: EarningsRead
