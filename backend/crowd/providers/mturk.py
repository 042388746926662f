"""The mturk provider: boto3's ``mturk`` client, to AWS or any MTurk-compatible endpoint (the
built-in marketplace included; ``mturk_client`` chooses it from the settings).

A unit is a HIT (its ExternalQuestion frames the unit's page), a submission an assignment, an
allow-list a qualification type, and our keys are UniqueRequestTokens, which MTurk remembers
for 24 hours (the caller's ledger outlives that). Fees are MTurk's published pricing: 20% of
rewards and bonuses, 40% of the rewards of HITs with 10 or more assignments, at least one cent
per assignment or bonus (``FEES``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping, Sequence
from datetime import UTC, datetime, timedelta
from typing import Any
from urllib.parse import parse_qs, urlsplit
from xml.sax.saxutils import escape

from backend.annotation.tokens import TASK_SCOPE
from backend.config import Settings
from backend.crowd import pricing
from backend.crowd.provider import (
    BonusOrder,
    Completion,
    FeeSchedule,
    ProviderName,
    ProviderRefused,
    PublishedUnit,
    Requirements,
    SubmissionRecord,
    SubmissionStatus,
    UnitSpec,
    UnitState,
    decided_already,
)
from backend.crowd.providers.mturk_client import (
    MarketplaceError,
    MTurkClient,
    builtin_endpoint,
    call,
    call_naming,
    make_client,
    paginate,
)
from backend.errors import Conflict, Unauthorized
from backend.instance import public_url
from backend.security import verify_token

EXTERNAL_QUESTION_NS = ("http://mechanicalturk.amazonaws.com/AWSMechanicalTurkDataSchemas/"
                        "2006-07-14/ExternalQuestion.xsd")
TRAINING_QUALIFICATION = "dexlabel: passed training"
# MTurk's system qualification types.
PERCENT_APPROVED = "000000000000000000L0"
LOCALE = "00000000000000000071"
# The assignment statuses ``submissions`` collects, and ours for each.
STATUSES: dict[str, SubmissionStatus] = {"Submitted": "submitted", "Approved": "approved",
                                         "Rejected": "rejected"}
# MTurk expires a HIT at once when ExpireAt lies in the past.
_PAST = datetime(2015, 1, 1, tzinfo=UTC)
# Where a worker's browser posts the finished page, per endpoint.
WORKER_SUBMIT = {
    "https://mturk-requester.us-east-1.amazonaws.com":
        "https://www.mturk.com/mturk/externalSubmit",
    "https://mturk-requester-sandbox.us-east-1.amazonaws.com":
        "https://workersandbox.mturk.com/mturk/externalSubmit",
}

# MTurk's smallest reward per assignment (the built-in marketplace keeps it too).
MIN_REWARD_CENTS = 1

FEES = FeeSchedule(provider="mturk", currency="USD", reward_rate=0.20, large_unit_rate=0.40,
                   large_unit_places=10, bonus_rate=0.20, min_fee_cents=1)


def external_question(page_url: str, frame_height: int) -> str:
    """The ExternalQuestion XML: the unit's page, in MTurk's iframe."""
    return (f'<ExternalQuestion xmlns="{EXTERNAL_QUESTION_NS}">'
            f"<ExternalURL>{escape(page_url)}</ExternalURL>"
            f"<FrameHeight>{frame_height}</FrameHeight></ExternalQuestion>")


def task_of_question(question: str, signing_key: str) -> int | None:
    """The task whose page an ExternalQuestion shows (the task token in its URL), or None."""
    try:
        root = ET.fromstring(question)
    except ET.ParseError:
        return None
    url = next((node.text or "" for node in root.iter() if node.tag.endswith("ExternalURL")), "")
    tokens = parse_qs(urlsplit(url.strip()).query).get("task", [])
    if not tokens:
        return None
    try:
        claims = verify_token(tokens[0], signing_key, TASK_SCOPE)
    except Unauthorized:
        return None
    return int(claims["task_id"])


def qualification_requirements(requirements: Requirements) -> list[dict[str, Any]]:
    """MTurk's QualificationRequirements for our Requirements (``assignee`` has no MTurk
    form: a HIT cannot be offered to one worker)."""
    reqs: list[dict[str, Any]] = []
    if requirements.min_approval_rate is not None:
        reqs.append({"QualificationTypeId": PERCENT_APPROVED, "Comparator": "GreaterThanOrEqualTo",
                     "IntegerValues": [requirements.min_approval_rate],
                     "ActionsGuarded": "Accept"})
    if requirements.locales:
        reqs.append({"QualificationTypeId": LOCALE, "Comparator": "In",
                     "LocaleValues": [{"Country": c} for c in requirements.locales],
                     "ActionsGuarded": "Accept"})
    if requirements.group:
        reqs.append({"QualificationTypeId": requirements.group, "Comparator": "Exists",
                     "ActionsGuarded": "DiscoverPreviewAndAccept"})
    return reqs


def hit_params(unit: UnitSpec) -> dict[str, Any]:
    """CreateHIT's parameters for one unit."""
    return {
        "Title": unit.title, "Description": unit.description, "Keywords": unit.keywords,
        "Reward": pricing.cents_to_dollars(unit.reward_cents), "MaxAssignments": unit.places,
        "LifetimeInSeconds": unit.lifetime_s, "AssignmentDurationInSeconds": unit.allotted_s,
        "AutoApprovalDelayInSeconds": unit.auto_approve_s,
        "Question": external_question(unit.page_url, unit.frame_height),
        "RequesterAnnotation": unit.note,
        "QualificationRequirements": qualification_requirements(unit.requirements),
        "UniqueRequestToken": unit.key,
    }


def _record(item: Mapping[str, Any]) -> SubmissionRecord:
    status = STATUSES.get(str(item.get("AssignmentStatus")), "held")
    return SubmissionRecord(assignment_id=item["AssignmentId"], unit_id=item["HITId"],
                            worker_id=item["WorkerId"], status=status)


class MTurkProvider:
    """The CrowdProvider of an MTurk-compatible endpoint. The boto3 client is made at the first
    call (or given: a client made elsewhere, e.g. with fewer retries)."""

    name: ProviderName = "mturk"
    # Each unit is a CreateHIT of its own: a run that commits per unit keeps every HIT made.
    publish_chunk = 1

    def __init__(self, settings: Settings, client: MTurkClient | None = None) -> None:
        self._settings = settings
        self._client = client

    @property
    def client(self) -> MTurkClient:
        if self._client is None:
            self._client = make_client(self._settings)
        return self._client

    def fees(self) -> FeeSchedule:
        return FEES

    def check_publish(self, units: Sequence[UnitSpec]) -> None:
        """Refuse a reward under MTurk's smallest, one cent (the schema takes 0, which only
        the team pays); the endpoint refuses the rest of what it cannot take."""
        for unit in units:
            if unit.reward_cents < MIN_REWARD_CENTS:
                detail = (f"reward: {pricing.cents_to_dollars(unit.reward_cents)} is less than "
                          f"the smallest reward MTurk pays, "
                          f"{pricing.cents_to_dollars(MIN_REWARD_CENTS)} (only team units may "
                          "pay 0)")
                raise ProviderRefused(detail, "check_publish",
                                      [{"field": "reward", "message": detail}])

    def publish(self, units: Sequence[UnitSpec]) -> list[PublishedUnit]:
        """One CreateHIT per unit; HitAlreadyExists (the token was used) recovers its HIT."""
        return [self._create(unit.key, hit_params(unit)) for unit in units]

    def _create(self, key: str, params: Mapping[str, Any]) -> PublishedUnit:
        """CreateHIT with ``params``; a HIT already made with this token is recovered."""
        try:
            reply = call(self.client, "create_hit", **params)
        except MarketplaceError as exc:
            if exc.reason != "already_exists":
                raise
            if exc.unit_id is None:
                raise MarketplaceError(
                    f"HIT already exists but its id is not in the reply: {exc.detail}",
                    exc.operation, exc.turk_code) from exc
            return PublishedUnit(key, exc.unit_id, "recovered")
        return PublishedUnit(key, reply["HIT"]["HITId"], "created")

    def _hit(self, unit_id: str) -> dict[str, Any] | None:
        """GetHIT's record of the unit; None where the marketplace has no such HIT."""
        try:
            hit: dict[str, Any] = call(self.client, "get_hit", HITId=unit_id)["HIT"]
        except MarketplaceError as exc:
            if exc.reason == "not_found":
                return None
            raise
        return hit

    def unit(self, unit_id: str) -> UnitState | None:
        hit = self._hit(unit_id)
        if hit is None:
            return None
        places = int(hit.get("MaxAssignments") or 0)
        held = int(hit.get("NumberOfAssignmentsPending") or 0)
        available = int(hit.get("NumberOfAssignmentsAvailable") or 0)
        return UnitState(
            unit_id=unit_id,
            task_id=task_of_question(str(hit.get("Question", "")), self._settings.signing_key),
            places=places, held=held, submitted=max(places - available - held, 0),
            allotted_s=int(hit.get("AssignmentDurationInSeconds") or 0),
            open=hit.get("HITStatus") == "Assignable")

    def submissions(self, unit_ids: Sequence[str]) -> Iterator[SubmissionRecord]:
        for unit_id in unit_ids:
            for item in paginate(self.client, "list_assignments_for_hit", "Assignments",
                                 HITId=unit_id, AssignmentStatuses=list(STATUSES)):
                yield _record(item)

    def submission(self, assignment_id: str) -> SubmissionRecord | None:
        """GetAssignment; None while MTurk does not show it (it shows an assignment to its
        requester only once submitted)."""
        try:
            reply = call(self.client, "get_assignment", AssignmentId=assignment_id)
        except MarketplaceError as exc:
            if exc.reason == "not_found":
                return None
            raise
        return _record(reply["Assignment"])

    def _decide(self, operation: str, assignment_id: str, feedback: str | None,
                done: SubmissionStatus) -> None:
        params = {"AssignmentId": assignment_id}
        if feedback:
            params["RequesterFeedback"] = feedback
        try:
            call(self.client, operation, **params)
        except MarketplaceError as exc:
            if not decided_already(self, exc, assignment_id, done):
                raise

    def approve(self, assignment_id: str, feedback: str | None) -> None:
        self._decide("approve_assignment", assignment_id, feedback, "approved")

    def reject(self, assignment_id: str, feedback: str, category: str | None) -> None:
        self._decide("reject_assignment", assignment_id, feedback, "rejected")

    def bonus_paid(self, order: BonusOrder) -> bool:
        """More payments of this amount and reason than ``same_paid`` (ListBonusPayments does
        not show tokens)."""
        matching = sum(
            1 for p in paginate(self.client, "list_bonus_payments", "BonusPayments",
                                AssignmentId=order.assignment_id)
            if pricing.dollars_to_cents(p["BonusAmount"]) == order.amount_cents
            and p["Reason"] == order.reason)
        return matching > order.same_paid

    def pay_bonus(self, order: BonusOrder) -> None:
        try:
            call(self.client, "send_bonus", WorkerId=order.worker_id,
                 AssignmentId=order.assignment_id,
                 BonusAmount=pricing.cents_to_dollars(order.amount_cents), Reason=order.reason,
                 UniqueRequestToken=order.key)
        except MarketplaceError as exc:
            # The token was used within 24 hours by an attempt whose reply was lost: paid.
            if exc.reason != "replayed":
                raise

    def extend(self, unit_id: str, seconds: int) -> None:
        call_naming(self.client, "update_expiration_for_hit", {"ExpireAt": "seconds"},
                    HITId=unit_id, ExpireAt=datetime.now(UTC) + timedelta(seconds=seconds))

    def close(self, unit_id: str) -> None:
        call(self.client, "update_expiration_for_hit", HITId=unit_id, ExpireAt=_PAST)

    def add_places(self, unit_id: str, count: int, key: str) -> None:
        call_naming(self.client, "create_additional_assignments_for_hit",
                    {"NumberOfAdditionalAssignments": "count"}, HITId=unit_id,
                    NumberOfAdditionalAssignments=count, UniqueRequestToken=key)

    def block(self, worker_id: str, reason: str) -> None:
        call(self.client, "create_worker_block", WorkerId=worker_id, Reason=reason)

    def unblock(self, worker_id: str, reason: str | None) -> None:
        params = {"WorkerId": worker_id}
        if reason:
            params["Reason"] = reason
        call(self.client, "delete_worker_block", **params)

    def training_group(self) -> str:
        """Creates our "passed training" qualification type (the caller keeps its id)."""
        try:
            reply = call(self.client, "create_qualification_type", Name=TRAINING_QUALIFICATION,
                         Keywords="dexlabel, training",
                         Description="Granted to workers who passed the dexlabel training task.",
                         QualificationTypeStatus="Active")
        except MarketplaceError as exc:
            if exc.reason == "already_exists":
                raise Conflict(f"the marketplace already has a qualification type named "
                               f"{TRAINING_QUALIFICATION!r} that this database does not "
                               "know") from exc
            raise
        return str(reply["QualificationType"]["QualificationTypeId"])

    def grant(self, worker_id: str, group: str, value: int, notify: bool) -> None:
        call_naming(self.client, "associate_qualification_with_worker",
                    {"IntegerValue": "value", "SendNotification": "notify"},
                    QualificationTypeId=group, WorkerId=worker_id, IntegerValue=value,
                    SendNotification=notify)

    def revoke(self, worker_id: str, group: str, reason: str | None) -> None:
        params = {"WorkerId": worker_id, "QualificationTypeId": group}
        if reason:
            params["Reason"] = reason
        call(self.client, "disassociate_qualification_from_worker", **params)

    def notify(self, worker_ids: Sequence[str], subject: str,
               message: str) -> list[dict[str, str]]:
        reply = call_naming(self.client, "notify_workers", {"MessageText": "message"},
                            WorkerIds=list(worker_ids), Subject=subject, MessageText=message)
        return list(reply.get("NotifyWorkersFailureStatuses", []))

    def completion(self, unit_id: str, assignment_id: str) -> Completion:
        """MTurk's externalSubmit form post: AWS's worker sites, the built-in marketplace's
        ``{PUBLIC_URL}/mturk/externalSubmit``; for another endpoint the url is empty and the
        page posts to the ``turkSubmitTo`` its address carries."""
        endpoint = str(self.client.meta.endpoint_url).rstrip("/")
        if endpoint in WORKER_SUBMIT:
            return Completion("form_post", WORKER_SUBMIT[endpoint])
        if endpoint == builtin_endpoint(self._settings):
            base = public_url(self._settings).rstrip("/")
            return Completion("form_post", f"{base}/mturk/externalSubmit")
        return Completion("form_post", "")


def make(settings: Settings) -> MTurkProvider:
    return MTurkProvider(settings)
