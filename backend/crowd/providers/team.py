"""The team crowd: the lab's own annotators, working in this instance's worker portal.

Units are HITs of the built-in marketplace this instance serves (whatever
DEXLABEL_MTURK_ENDPOINT_URL says), published by its team requester account
(``backend.config.team_market_requester``), so the portal lists them beside any other HIT.

Who is on the team: every portal account of this instance. The built-in marketplace has no
other workers (an account is made by an admin or through an invite), so an open team unit needs
no allow-list; leaving the team is having the account deactivated (or the worker blocked).

A unit whose requirements name an ``assignee`` (a portal account's worker id) is for that person
alone: it requires, to discover, preview and accept it, a qualification type of their own
("dexlabel team: A1B2..."), made on the first unit assigned to them, granted to them without a
message on every publish, and remembered in ``crowd_qualifications``. Nobody else holds it, so
the portal does not even list the unit to anyone else.

Pay is optional and never sent anywhere. The marketplace HIT offers 0 (the team account holds
and pays nothing there); the reward the lab chose, 0 or more, and every approval and bonus are
the crowd ledger's, written by the crowd domain. Fees are zero. Approvals and rejections reach
the marketplace (the member's portal shows the decision and its feedback); a bonus is checked
against the marketplace's record of the assignment and goes no further.

Ids: a unit id is the HIT id, an assignment id the marketplace's AssignmentId, a worker id the
portal account's worker id.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping, Sequence
from datetime import UTC, datetime, timedelta
from typing import Any
from xml.sax.saxutils import escape

from sqlalchemy import select

from backend.accounts.models import PortalAccount
from backend.config import Settings, team_market_requester
from backend.crowd.client import (
    MarketplaceError,
    MarketplaceRefused,
    MarketplaceUnreachable,
    MTurkClient,
    call_naming,
    make_client,
    paginate,
)
from backend.crowd.models import CrowdQualification
from backend.crowd.provider import (
    BonusOrder,
    Completion,
    CrowdProvider,
    FeeSchedule,
    ProviderError,
    ProviderName,
    ProviderRefused,
    ProviderUnreachable,
    PublishedUnit,
    Requirements,
    SubmissionRecord,
    SubmissionStatus,
    UnitSpec,
    UnitState,
)
from backend.db import session_scope
from backend.instance import public_url

EXTERNAL_QUESTION_NS = ("http://mechanicalturk.amazonaws.com/AWSMechanicalTurkDataSchemas/"
                        "2006-07-14/ExternalQuestion.xsd")
PERCENT_APPROVED = "000000000000000000L0"  # MTurk's system qualification type
ASSIGNEE_PREFIX = "dexlabel team: "  # + the assignee's worker id: their own qualification type
TRAINING_GROUP = "dexlabel team: passed training"
COLLECTED_STATUSES = ["Submitted", "Approved", "Rejected"]
_STATUS: dict[str, SubmissionStatus] = {"Submitted": "submitted", "Approved": "approved",
                                        "Rejected": "rejected"}
_REASONS = {
    "AWS.MechanicalTurk.HitAlreadyExists": "already_exists",
    "AWS.MechanicalTurk.InvalidAssignmentState": "invalid_state",
    "AWS.MechanicalTurk.InvalidHITState": "invalid_state",
    "AWS.MechanicalTurk.DuplicateRequest": "replayed",
}
_HIT_ID_IN_MESSAGE = re.compile(r"HIT\s?Id\W*([A-Za-z0-9]+)", re.IGNORECASE)
_TASK_IN_NOTE = re.compile(r"\btask (\d+)\b")
# The marketplace expires a HIT at once when ExpireAt lies in the past.
_PAST = datetime(2015, 1, 1, tzinfo=UTC)
NOTIFY_BATCH = 100  # NotifyWorkers takes at most 100 worker ids a call
FREE = FeeSchedule(provider="team", currency="USD", reward_rate=0.0, large_unit_rate=0.0,
                   large_unit_places=0, bonus_rate=0.0, min_fee_cents=0)


def _provider_error(exc: MarketplaceError) -> ProviderError:
    """The marketplace's refusal in the protocol's words."""
    if isinstance(exc, MarketplaceUnreachable):
        return ProviderUnreachable(exc.detail, exc.operation)
    if isinstance(exc, MarketplaceRefused):
        return ProviderRefused(exc.detail, exc.operation, exc.extra.get("fields"), exc.turk_code)
    reason = _REASONS.get(exc.turk_code) or (
        "not_found" if exc.turk_code.endswith("DoesNotExist") else
        "throttled" if exc.retryable else "other")
    match = _HIT_ID_IN_MESSAGE.search(exc.detail) if reason == "already_exists" else None
    return ProviderError(exc.detail, exc.operation, reason, exc.retryable,
                         unit_id=match.group(1) if match else None, provider_code=exc.turk_code)


def external_question(page_url: str, frame_height: int) -> str:
    """The ExternalQuestion XML that frames the annotation page in the portal."""
    return (f'<ExternalQuestion xmlns="{EXTERNAL_QUESTION_NS}">'
            f"<ExternalURL>{escape(page_url)}</ExternalURL>"
            f"<FrameHeight>{frame_height}</FrameHeight></ExternalQuestion>")


def _refused(detail: str, field: str) -> ProviderRefused:
    return ProviderRefused(detail, "check_publish", [{"field": field, "message": detail}])


def check_assignee(worker_id: str) -> None:
    """Refuse an assignee who is not an active portal account of this instance."""
    with session_scope() as session:
        account = session.scalar(select(PortalAccount).where(
            PortalAccount.worker_id == worker_id))
        if account is None:
            raise _refused(f"assignee {worker_id}: no portal account has this worker id",
                           "assignee")
        if not account.active:
            raise _refused(f"assignee {worker_id}: the portal account {account.email} is "
                           "deactivated", "assignee")


class TeamProvider:
    """The team crowd on the built-in marketplace's team requester account."""

    name: ProviderName = "team"

    def __init__(self, client: MTurkClient, portal_url: str) -> None:
        self._client = client
        self._portal_url = portal_url

    def _call(self, operation: str, fields: Mapping[str, str] | None = None, /,
              **params: Any) -> dict[str, Any]:
        try:
            return call_naming(self._client, operation, fields, **params)
        except MarketplaceError as exc:
            raise _provider_error(exc) from exc

    def fees(self) -> FeeSchedule:
        return FREE

    def check_publish(self, units: Sequence[UnitSpec]) -> None:
        """Refuse a negative reward, no places, a locale requirement (portal accounts have no
        locale, so nobody could take the unit) and an assignee without a portal account."""
        for unit in units:
            if unit.reward_cents < 0:
                raise _refused(f"reward {unit.reward_cents} cents is negative", "reward")
            if unit.places < 1:
                raise _refused(f"places must be at least 1, got {unit.places}", "max_assignments")
            if unit.requirements.locales:
                raise _refused("team units take no locale requirement: portal accounts have "
                               "no locale", "locales")
        for assignee in {u.requirements.assignee for u in units} - {None}:
            assert assignee is not None
            check_assignee(assignee)

    def publish(self, units: Sequence[UnitSpec]) -> list[PublishedUnit]:
        self.check_publish(units)
        granted: dict[str, str] = {}
        for assignee in {u.requirements.assignee for u in units} - {None}:
            assert assignee is not None
            granted[assignee] = self._group(ASSIGNEE_PREFIX + assignee,
                                            f"Team tasks assigned to {assignee}")
            self.grant(assignee, granted[assignee], 1, notify=False)
        return [self._publish_one(unit, granted) for unit in units]

    def _requirements(self, wanted: Requirements, granted: dict[str, str]) -> list[dict]:
        reqs: list[dict] = []
        if wanted.min_approval_rate is not None:
            reqs.append({"QualificationTypeId": PERCENT_APPROVED,
                         "Comparator": "GreaterThanOrEqualTo",
                         "IntegerValues": [wanted.min_approval_rate], "ActionsGuarded": "Accept"})
        reqs.extend({"QualificationTypeId": type_id, "Comparator": "Exists",
                     "ActionsGuarded": "DiscoverPreviewAndAccept"}
                    for type_id in (wanted.group, granted.get(wanted.assignee or "")) if type_id)
        return reqs

    def _publish_one(self, unit: UnitSpec, granted: dict[str, str]) -> PublishedUnit:
        try:
            reply = self._call(
                "create_hit", {"MaxAssignments": "max_assignments"},
                Title=unit.title, Description=unit.description, Keywords=unit.keywords,
                Reward="0.00", MaxAssignments=unit.places, LifetimeInSeconds=unit.lifetime_s,
                AssignmentDurationInSeconds=unit.allotted_s,
                AutoApprovalDelayInSeconds=unit.auto_approve_s,
                Question=external_question(unit.page_url, unit.frame_height),
                RequesterAnnotation=unit.note,
                QualificationRequirements=self._requirements(unit.requirements, granted),
                UniqueRequestToken=unit.key)
        except ProviderError as exc:
            if exc.reason != "already_exists" or exc.unit_id is None:
                raise
            return PublishedUnit(unit.key, exc.unit_id, "recovered")
        return PublishedUnit(unit.key, reply["HIT"]["HITId"], "created")

    def _group(self, name: str, description: str) -> str:
        """The team account's qualification type ``name``, made on the marketplace once and
        remembered in its own short transaction (like the marketplace's own writes: the
        caller holds no write across provider calls)."""
        with session_scope() as session:
            known = session.scalar(select(CrowdQualification.qualification_type_id).where(
                CrowdQualification.name == name))
        if known is not None:
            return known
        reply = self._call("create_qualification_type", Name=name, Description=description,
                           Keywords="dexlabel, team", QualificationTypeStatus="Active")
        type_id: str = reply["QualificationType"]["QualificationTypeId"]
        with session_scope() as session:
            session.add(CrowdQualification(name=name, qualification_type_id=type_id))
        return type_id

    def unit(self, unit_id: str) -> UnitState | None:
        try:
            hit = self._call("get_hit", HITId=unit_id)["HIT"]
        except ProviderError as exc:
            if exc.reason == "not_found":
                return None
            raise
        task = _TASK_IN_NOTE.search(hit.get("RequesterAnnotation") or "")
        return UnitState(
            unit_id=unit_id, task_id=int(task.group(1)) if task else None,
            places=hit["MaxAssignments"], held=hit["NumberOfAssignmentsPending"],
            submitted=sum(1 for _ in self.submissions([unit_id])),
            allotted_s=hit["AssignmentDurationInSeconds"],
            open=hit["HITStatus"] != "Disposed" and hit["Expiration"] > datetime.now(UTC))

    def submissions(self, unit_ids: Sequence[str]) -> Iterator[SubmissionRecord]:
        for unit_id in unit_ids:
            try:
                for item in paginate(self._client, "list_assignments_for_hit", "Assignments",
                                     HITId=unit_id, AssignmentStatuses=COLLECTED_STATUSES):
                    yield _record(item)
            except MarketplaceError as exc:
                raise _provider_error(exc) from exc

    def submission(self, assignment_id: str) -> SubmissionRecord | None:
        try:
            reply = self._call("get_assignment", AssignmentId=assignment_id)
        except ProviderError as exc:
            if exc.reason == "not_found":
                return None
            raise
        return _record(reply["Assignment"])

    def _decide(self, operation: str, assignment_id: str, feedback: str | None,
                done: SubmissionStatus) -> None:
        params = {"RequesterFeedback": feedback} if feedback else {}
        try:
            self._call(operation, {"RequesterFeedback": "feedback"},
                       AssignmentId=assignment_id, **params)
        except ProviderError as exc:
            # Decided by an earlier call whose reply was lost: the same decision is done.
            found = self.submission(assignment_id) if exc.reason == "invalid_state" else None
            if found is None or found.status != done:
                raise

    def approve(self, assignment_id: str, feedback: str | None) -> None:
        self._decide("approve_assignment", assignment_id, feedback, "approved")

    def reject(self, assignment_id: str, feedback: str, category: str | None) -> None:
        self._decide("reject_assignment", assignment_id, feedback, "rejected")

    def bonus_paid(self, order: BonusOrder) -> bool:
        """Never: a team bonus is paid nowhere, so the ledger's row is the whole of it."""
        return False

    def pay_bonus(self, order: BonusOrder) -> None:
        """Nothing is sent: the bonus is the ledger's row. Refuses an assignment the team
        account does not know, so a wrong id is not recorded as paid."""
        if self.submission(order.assignment_id) is None:
            raise ProviderError(f"assignment {order.assignment_id} is not a team submission",
                                "pay_bonus", "not_found")

    def extend(self, unit_id: str, seconds: int) -> None:
        self._call("update_expiration_for_hit", {"ExpireAt": "seconds"}, HITId=unit_id,
                   ExpireAt=datetime.now(UTC) + timedelta(seconds=seconds))

    def close(self, unit_id: str) -> None:
        self._call("update_expiration_for_hit", HITId=unit_id, ExpireAt=_PAST)

    def add_places(self, unit_id: str, count: int, key: str) -> None:
        self._call("create_additional_assignments_for_hit",
                   {"NumberOfAdditionalAssignments": "count"}, HITId=unit_id,
                   NumberOfAdditionalAssignments=count, UniqueRequestToken=key)

    def block(self, worker_id: str, reason: str) -> None:
        self._call("create_worker_block", WorkerId=worker_id, Reason=reason)

    def unblock(self, worker_id: str, reason: str | None) -> None:
        self._call("delete_worker_block", WorkerId=worker_id,
                   **({"Reason": reason} if reason else {}))

    def training_group(self) -> str:
        return self._group(TRAINING_GROUP, "Team members who passed the dexlabel training task.")

    def grant(self, worker_id: str, group: str, value: int, notify: bool) -> None:
        self._call("associate_qualification_with_worker", QualificationTypeId=group,
                   WorkerId=worker_id, IntegerValue=value, SendNotification=notify)

    def revoke(self, worker_id: str, group: str, reason: str | None) -> None:
        self._call("disassociate_qualification_from_worker", QualificationTypeId=group,
                   WorkerId=worker_id, **({"Reason": reason} if reason else {}))

    def notify(self, worker_ids: Sequence[str], subject: str,
               message: str) -> list[dict[str, str]]:
        failures: list[dict[str, str]] = []
        for start in range(0, len(worker_ids), NOTIFY_BATCH):
            reply = self._call("notify_workers", {"MessageText": "message"}, Subject=subject,
                               MessageText=message,
                               WorkerIds=list(worker_ids[start:start + NOTIFY_BATCH]))
            failures += [{"worker_id": f["WorkerId"], "code": f["NotifyWorkersFailureCode"],
                          "message": f["NotifyWorkersFailureMessage"]}
                         for f in reply.get("NotifyWorkersFailureStatuses", [])]
        return failures

    def completion(self, unit_id: str, assignment_id: str) -> Completion:
        """Back to the portal's list of tasks."""
        return Completion("portal", self._portal_url)


def _record(item: dict[str, Any]) -> SubmissionRecord:
    return SubmissionRecord(assignment_id=item["AssignmentId"], unit_id=item["HITId"],
                            worker_id=item["WorkerId"], status=_STATUS[item["AssignmentStatus"]])


def team_settings(settings: Settings) -> Settings:
    """``settings`` pointed at the built-in marketplace with the team account's key pair."""
    team = team_market_requester(settings.signing_key)
    return settings.model_copy(update={
        "mturk_endpoint_url": None, "mturk_use_aws": False,
        "mturk_access_key_id": team.access_key, "mturk_secret_access_key": team.secret_key})


def make(settings: Settings) -> CrowdProvider:
    """The team provider of this instance."""
    portal = public_url(settings).rstrip("/") + "/market/"
    return TeamProvider(make_client(team_settings(settings)), portal)
