"""Requests and replies of the crowd endpoints; amounts in US dollars on the wire."""

from __future__ import annotations

from datetime import datetime
from decimal import Decimal
from typing import Annotated, Literal

from pydantic import BaseModel, Field

from backend.crowd.provider import ProviderName
from backend.validation import BodyId, Int32

# MTurk's own bounds: lifetime 30 s to 1 year, assignment duration 30 s to 1 year,
# auto-approval delay 0 to 30 days.
Seconds = Annotated[int, Field(ge=30, le=31_536_000)]
# A reward may be 0 (a team unit's, pay being optional for the lab's own annotators); each
# provider refuses what is under its own floor in check_publish (MTurk: one cent, Prolific:
# its minimum hourly rate), naming the field reward.
Reward = Annotated[Decimal, Field(ge=Decimal(0), le=1000, decimal_places=2)]
Feedback = Annotated[str, Field(min_length=1, max_length=1024)]
PublishPolicy = Literal["every-view", "adaptive"]


class PublishOptions(BaseModel):
    """How tasks are published. Rewards in dollars, durations in seconds."""

    reward: Reward = Decimal("0.50")
    max_assignments: int = Field(default=1, ge=1, le=1_000_000_000)
    # 10+ assignments per HIT cost 20% more in fees: it must be asked for explicitly.
    allow_large_hits: bool = False
    round: int = Field(default=1, ge=1, le=1000)
    lifetime_s: Seconds = 7 * 24 * 3600
    assignment_duration_s: Seconds = 2 * 3600
    auto_approval_delay_s: int = Field(default=3 * 24 * 3600, ge=0, le=2_592_000)
    keywords: str = Field(default="hand, keypoints, tracking, video, annotation", max_length=1000)
    frame_height: int = Field(default=900, ge=0, le=4000)
    min_approval_rate: int | None = Field(default=95, ge=0, le=100)
    locales: list[Annotated[str, Field(pattern=r"^[A-Z]{2}$")]] = Field(default_factory=list)
    require_training: bool = False
    # The crowd to publish to (unset: the setting DEXLABEL_CROWD_PROVIDER).
    provider: ProviderName | None = None
    # team only: the portal worker id of the one annotator the tasks are assigned to.
    assignee: str | None = Field(default=None, min_length=1, max_length=64)
    # Which views are published (backend.crowd.adaptive; unset: the DEXLABEL_PUBLISH_*
    # settings): every view at once, or adaptive (the initial views of widest baseline, then
    # one more after each solve while too few frames reach the confidence).
    policy: PublishPolicy | None = None
    initial_views: int | None = Field(default=None, ge=2, le=64)
    confidence: float | None = Field(default=None, gt=0, le=1)
    confident_share: float | None = Field(default=None, gt=0, le=1)


class PublishRequest(PublishOptions):
    sequence_id: BodyId | None = None
    dry_run: bool = False


class CostRead(BaseModel):
    """What a publish costs when every place is approved, in the provider's fees and
    currency (amounts as decimal strings in that currency)."""

    provider: ProviderName = "mturk"
    currency: str = "USD"
    hits: int
    assignments_per_hit: int
    reward: str
    fee_per_assignment: str
    rewards: str
    fees: str
    total: str


class PublishResult(BaseModel):
    cost: CostRead
    created: int = 0
    recovered: int = 0
    already_published: int = 0
    hit_ids: list[str] = Field(default_factory=list)


class SyncResult(BaseModel):
    hits: int
    accepted: int
    already_accepted: int
    mismatched: list[str]
    unknown: list[str]
    # Our assignment ids of the submissions accepted by this sync (each goes on to QC).
    accepted_ids: list[int] = []


class ApproveRequest(BaseModel):
    feedback: Feedback | None = None


class RejectRequest(BaseModel):
    feedback: Feedback
    # The provider's reason code where it wants one (Prolific's rejection_category, e.g.
    # LOW_EFFORT); MTurk and the team take none.
    category: str | None = Field(default=None, min_length=1, max_length=32,
                                 pattern=r"^[A-Z_]+$")


class BonusRequest(BaseModel):
    amount: Annotated[Decimal, Field(gt=0, le=100, decimal_places=2)]
    reason: Feedback
    # Names this bonus among the assignment's bonuses: the same key never pays twice.
    key: Annotated[str, Field(min_length=1, max_length=32, pattern=r"^[A-Za-z0-9_-]+$")] = "1"


class PaymentRead(BaseModel):
    kind: str
    assignment_id: int
    worker_id: str
    amount: str
    fee: str
    already_done: bool = False


class ExtendRequest(BaseModel):
    seconds: Annotated[int, Field(ge=60, le=31_536_000)]


class AddAssignmentsRequest(BaseModel):
    count: Annotated[int, Field(ge=1, le=1_000_000_000)]
    allow_large_hits: bool = False


class QualificationRequest(BaseModel):
    # Unset: our "passed training" type.
    qualification_type_id: str | None = Field(default=None, min_length=1, max_length=64)
    value: Int32 = 1
    notify: bool = False


class NotifyRequest(BaseModel):
    worker_ids: Annotated[list[str], Field(min_length=1, max_length=100)]
    subject: Annotated[str, Field(min_length=1, max_length=200)]
    message: Annotated[str, Field(min_length=1, max_length=4096)]


class BlockRequest(BaseModel):
    reason: Feedback


class CostLine(BaseModel):
    """Money of one project, sequence or worker, in dollars.

    spent: approved rewards and paid bonuses, each with the provider's fee. committed: what is still
    held for it: open slots of live HITs and submitted work not yet decided (reward + fee), and
    bonuses started but not yet confirmed paid (bonus + fee).
    """

    key: str
    # What people call it: a sequence's "subject/name", a worker's id, "project".
    name: str = ""
    spent: str
    spent_rewards: str
    spent_bonuses: str
    spent_fees: str
    committed: str
    committed_rewards: str
    committed_bonuses: str
    committed_fees: str
    # The currency of the amounts ("mixed" on a total over providers of different ones).
    currency: str = "USD"


class CostsRead(BaseModel):
    total: CostLine
    by_sequence: list[CostLine]
    by_worker: list[CostLine]
    # Per crowd provider, each in its own currency and fees.
    by_provider: list[CostLine] = Field(default_factory=list)


class WorkerReportPoint(BaseModel):
    """One QC report of a worker, for their quality over time."""

    assignment_id: int
    at: datetime
    outcome: str
    provisional: bool
    # The report's median reprojection error, px; null where no consensus measured it.
    median_error_px: float | None


class WorkerStatsRead(BaseModel):
    """A worker's record in this project; money in dollars (fees apart), times in seconds."""

    worker_id: str
    # Assignments submitted (whatever became of them), approved and rejected.
    submitted: int
    approved: int
    rejected: int
    # approved / (approved + rejected); null before any decision.
    approval_rate: float | None
    # Final QC reports and the running QC score over them (as GET /api/qc/workers counts).
    scored: int
    score: float | None
    median_error_px: float | None
    median_working_time_s: float | None
    earned_rewards: str
    earned_bonuses: str
    earned: str
    blocked: bool
    block_reason: str | None
    # QC reports by date, oldest first (the newest few in a listing).
    history: list[WorkerReportPoint]


class WorkerAssignmentRead(BaseModel):
    assignment_id: int
    task_id: int
    sequence_id: int
    sequence: str
    target_key: str
    status: str
    submitted_at: datetime | None
    working_time_s: float
    # The HIT's reward (null for work from a direct link) and the bonuses paid on it.
    reward: str | None
    bonuses: str
    # Whether the marketplace confirmed the submission: only then can it be paid a bonus.
    confirmed: bool
    qc_outcome: str | None
    median_error_px: float | None


class WorkerDetailRead(WorkerStatsRead):
    assignments: list[WorkerAssignmentRead]
