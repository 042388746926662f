"""The one door between the crowd domain and any crowd: ``CrowdProvider``.

A provider publishes a task's units of work (an MTurk HIT, one entry of a Prolific Taskflow
study, a team task in the built-in portal), reports who holds and who submitted them, and
carries out the requester's decisions (approve, reject, bonus), the unit's life (extend, close,
add places) and the worker's standing (block, allow-list groups, messages). Everything here is
in our own words: ids are the provider's opaque strings, amounts are integer cents in the
provider's currency, statuses are the few ``SubmissionStatus`` values.

The crowd domain (publish, sync, decisions, actions, holds, confirm) talks only to this
protocol; the implementations live in ``backend.crowd.providers`` and are the only modules
that import a provider's SDK or name its operations (lint enforces it).

Errors: a provider raises ``ProviderError`` (or ``ProviderRefused`` for the caller's values,
``ProviderUnreachable`` when it did not answer), with ``reason`` one of ``REASONS`` so callers
decide without knowing the provider's error codes.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Literal, Protocol, runtime_checkable

from backend.errors import DexlabelError

ProviderName = Literal["mturk", "prolific", "team"]
PROVIDERS: tuple[ProviderName, ...] = ("mturk", "prolific", "team")

# What a submission is, as every provider's statuses map onto it.
#   held: a worker holds the unit and has not submitted (MTurk Accepted, Prolific ACTIVE/RESERVED)
#   submitted: waiting for our decision (MTurk Submitted, Prolific AWAITING REVIEW)
#   approved / rejected: decided
#   returned: the worker gave it back or timed out (Prolific RETURNED/TIMED-OUT/SCREENED OUT)
SubmissionStatus = Literal["held", "submitted", "approved", "rejected", "returned"]
# The statuses ``crowd sync`` collects.
COLLECTED: frozenset[str] = frozenset({"submitted", "approved", "rejected"})

# ProviderError.reason values.
#   already_exists: a publish with this key was done before (the unit id is in ``unit_id``)
#   invalid_state: the submission or unit is not in a state that allows the call
#   not_found: the provider has no such unit, submission or worker
#   refused: the caller's values were refused (ProviderRefused, 422)
#   throttled: "not now" (429/5xx); retryable
#   replayed: the idempotency key was already used (the call had been carried out)
#   other: anything else
REASONS = ("already_exists", "invalid_state", "not_found", "refused", "throttled", "replayed",
           "other")


class ProviderError(DexlabelError):
    """A crowd provider refused or failed a request (502 unless a subclass says otherwise)."""

    status_code = 502
    code = "provider_error"

    def __init__(self, detail: str, operation: str, reason: str = "other",
                 retryable: bool = False, unit_id: str | None = None,
                 provider_code: str = "") -> None:
        super().__init__(detail, operation=operation)
        self.operation = operation
        self.reason = reason
        self.retryable = retryable or reason == "throttled"
        self.unit_id = unit_id
        self.provider_code = provider_code


class ProviderRefused(ProviderError):
    """The provider refused the request's values: the caller's input, so 422; ``fields``
    names our fields it objected to."""

    status_code = 422
    code = "provider_refused"

    def __init__(self, detail: str, operation: str,
                 fields: list[dict[str, str]] | None = None, provider_code: str = "") -> None:
        super().__init__(detail, operation, "refused", provider_code=provider_code)
        if fields:
            self.extra["fields"] = fields


class ProviderUnreachable(ProviderError):
    """No answer from the provider (refused connection, timeout, TLS)."""

    code = "provider_unreachable"

    def __init__(self, detail: str, operation: str) -> None:
        super().__init__(detail, operation, "throttled", retryable=True)


@dataclass(frozen=True)
class Requirements:
    """Who may take a unit. ``group`` is an allow-list the provider keeps (an MTurk
    qualification type, a Prolific participant group, a team member list); ``assignee`` names
    the one worker (a portal account's worker id) a team task is assigned to."""

    min_approval_rate: int | None = None
    locales: tuple[str, ...] = ()
    group: str | None = None
    assignee: str | None = None


@dataclass(frozen=True)
class UnitSpec:
    """One unit of work to publish: a task in a round."""

    key: str  # our idempotency key, deterministic per (task, round): the ledger's request token
    task_id: int
    title: str
    description: str
    keywords: str
    page_url: str  # the annotation page for this task (carries the task token)
    reward_cents: int
    places: int  # how many workers may each do it once (MTurk MaxAssignments)
    lifetime_s: int
    allotted_s: int  # how long one worker may hold it
    auto_approve_s: int
    expected_s: int  # the expected working time, for pay floors
    frame_height: int
    note: str  # shown to the requester only ("dexlabel task 12 round 1")
    requirements: Requirements = field(default_factory=Requirements)


@dataclass(frozen=True)
class PublishedUnit:
    key: str
    unit_id: str
    outcome: Literal["created", "recovered"]


@dataclass(frozen=True)
class UnitState:
    """What the provider says of one unit now."""

    unit_id: str
    task_id: int | None  # the task its page shows, where the provider can tell
    places: int
    held: int  # places held by workers who have not submitted
    submitted: int
    allotted_s: int
    open: bool


@dataclass(frozen=True)
class SubmissionRecord:
    """One worker's take of one unit, as the provider records it."""

    assignment_id: str  # the provider's id of this take (MTurk AssignmentId, Prolific submission)
    unit_id: str
    worker_id: str
    status: SubmissionStatus


@dataclass(frozen=True)
class BonusOrder:
    """A bonus the ledger holds as pending; ``same_paid`` counts the done bonuses of this
    assignment with the same amount and reason, so ``bonus_paid`` can tell this one apart."""

    key: str  # our idempotency key (the ledger's request token)
    assignment_id: str
    unit_id: str
    worker_id: str
    amount_cents: int
    reason: str
    same_paid: int = 0


@dataclass(frozen=True)
class FeeSchedule:
    """A provider's fees as rates on rewards and bonuses, in its currency."""

    provider: ProviderName
    currency: str  # "USD", "GBP"
    reward_rate: float  # e.g. 0.20
    large_unit_rate: float  # the rate for units of ``large_unit_places`` places or more
    large_unit_places: int  # 0: no such rule
    bonus_rate: float
    min_fee_cents: int

    def reward_fee_cents(self, reward_cents: int, places: int = 1) -> int:
        large = self.large_unit_places and places >= self.large_unit_places
        return self._fee(reward_cents, self.large_unit_rate if large else self.reward_rate)

    def bonus_fee_cents(self, amount_cents: int) -> int:
        return self._fee(amount_cents, self.bonus_rate)

    def _fee(self, amount_cents: int, rate: float) -> int:
        if amount_cents <= 0 or rate <= 0:
            return 0
        return max(int(amount_cents * rate + 0.5), self.min_fee_cents)


@dataclass(frozen=True)
class Completion:
    """How the annotation page hands a finished unit back to the provider.

    ``form_post``: post the completion form to ``url`` (MTurk's externalSubmit);
    ``redirect``: send the browser to ``url`` (Prolific's completion link with its code);
    ``portal``: back to the portal's list at ``url`` (team).
    """

    kind: Literal["form_post", "redirect", "portal"]
    url: str


@runtime_checkable
class CrowdProvider(Protocol):
    """One crowd. Every call that publishes or pays is idempotent by our key."""

    name: ProviderName

    def fees(self) -> FeeSchedule: ...

    def check_publish(self, units: Sequence[UnitSpec]) -> None:
        """Refuse, before any call, units this provider cannot take (a reward under its pay
        floor, too many places): ProviderRefused naming the field."""

    def publish(self, units: Sequence[UnitSpec]) -> list[PublishedUnit]:
        """Publish the units (one provider-side batch where the provider has one); a unit
        whose key was published before comes back "recovered" with its unit id."""

    def unit(self, unit_id: str) -> UnitState | None: ...

    def submissions(self, unit_ids: Sequence[str]) -> Iterator[SubmissionRecord]:
        """Every collected (submitted, approved, rejected) take of these units."""

    def submission(self, assignment_id: str) -> SubmissionRecord | None:
        """One take, or None where the provider does not know it (yet)."""

    def approve(self, assignment_id: str, feedback: str | None) -> None:
        """Approve; already approved is not an error."""

    def reject(self, assignment_id: str, feedback: str, category: str | None) -> None:
        """Reject with feedback (Prolific: at least 100 characters and a category, checked
        before any call); already rejected is not an error."""

    def bonus_paid(self, order: BonusOrder) -> bool:
        """Whether the provider shows this pending bonus as paid already."""

    def pay_bonus(self, order: BonusOrder) -> None:
        """Pay the bonus once (the caller wrote the ledger row first)."""

    def extend(self, unit_id: str, seconds: int) -> None: ...

    def close(self, unit_id: str) -> None:
        """Stop new workers taking the unit (MTurk: expire; Prolific: no places left)."""

    def add_places(self, unit_id: str, count: int, key: str) -> None: ...

    def block(self, worker_id: str, reason: str) -> None: ...

    def unblock(self, worker_id: str, reason: str | None) -> None: ...

    def training_group(self) -> str:
        """The allow-list of workers who passed our training (created once)."""

    def grant(self, worker_id: str, group: str, value: int, notify: bool) -> None: ...

    def revoke(self, worker_id: str, group: str, reason: str | None) -> None: ...

    def notify(self, worker_ids: Sequence[str], subject: str,
               message: str) -> list[dict[str, str]]:
        """Message workers; the per-worker failures (empty when all went out)."""

    def completion(self, unit_id: str, assignment_id: str) -> Completion: ...


def decided_already(crowd: CrowdProvider, exc: ProviderError, assignment_id: str,
                    done: SubmissionStatus) -> bool:
    """Whether a provider's refusal of a decision means an earlier run (whose reply or commit
    was lost) already made it: the submission is in no state for it, and shows ``done``."""
    if exc.reason != "invalid_state":
        return False
    found = crowd.submission(assignment_id)
    return found is not None and found.status == done
