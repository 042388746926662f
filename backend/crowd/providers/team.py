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

The provider is the mturk provider on that account, differing only where the team does: no
fees, its own checks before publishing (locales, assignees), the assignee's qualification,
bonuses recorded and never sent, its own training allow-list and the portal as the place a
finished page goes back to. A minimum approval rate is ignored: every member is the lab's own,
and a new member has no approval record to meet it with.

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
from collections.abc import Sequence
from datetime import UTC, datetime

from sqlalchemy import select

from backend.accounts.models import PortalAccount
from backend.config import Settings, team_market_requester
from backend.crowd.models import CrowdQualification
from backend.crowd.provider import (
    BonusOrder,
    Completion,
    FeeSchedule,
    ProviderError,
    ProviderName,
    ProviderRefused,
    PublishedUnit,
    Requirements,
    UnitSpec,
    UnitState,
)
from backend.crowd.providers.mturk import (
    MTurkProvider,
    external_question,
    hit_params,
    qualification_requirements,
)
from backend.crowd.providers.mturk_client import call
from backend.db import session_scope
from backend.instance import public_url

__all__ = ["TeamProvider", "external_question", "make", "team_settings"]

ASSIGNEE_PREFIX = "dexlabel team: "  # + the assignee's worker id: their own qualification type
TRAINING_GROUP = "dexlabel team: passed training"
_TASK_IN_NOTE = re.compile(r"\btask (\d+)\b")
FREE = FeeSchedule(provider="team", currency="USD", reward_rate=0.0, large_unit_rate=0.0,
                   large_unit_places=0, bonus_rate=0.0, min_fee_cents=0)
# The portal's list of HITs, where a finished team page goes back to.
PORTAL_HITS = "/market/#/hits"


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


class TeamProvider(MTurkProvider):
    """The team crowd: the mturk provider on the built-in marketplace's team requester
    account (``settings`` are the team's: see ``team_settings``)."""

    name: ProviderName = "team"

    def fees(self) -> FeeSchedule:
        return FREE

    def check_publish(self, units: Sequence[UnitSpec]) -> None:
        """Refuse a negative reward (0 is a team unit's own), no places, a locale requirement
        (portal accounts have no locale, so nobody could take the unit) and an assignee
        without a portal account."""
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
        """The units as HITs that offer 0 on the marketplace (the lab's reward is the
        ledger's), an assigned one behind its assignee's own qualification."""
        self.check_publish(units)
        granted: dict[str, str] = {}
        for assignee in {u.requirements.assignee for u in units} - {None}:
            assert assignee is not None
            granted[assignee] = self._group(ASSIGNEE_PREFIX + assignee,
                                            f"Team tasks assigned to {assignee}")
            self.grant(assignee, granted[assignee], 1, notify=False)
        return [self._create(unit.key, {
            **hit_params(unit), "Reward": "0.00",
            "QualificationRequirements": _requirements(unit.requirements, granted)})
            for unit in units]

    def _group(self, name: str, description: str) -> str:
        """The team account's qualification type ``name``, made on the marketplace once and
        remembered in its own short transaction (like the marketplace's own writes: the
        caller holds no write across provider calls)."""
        with session_scope() as session:
            known = session.scalar(select(CrowdQualification.qualification_type_id).where(
                CrowdQualification.name == name))
        if known is not None:
            return known
        reply = call(self.client, "create_qualification_type", Name=name,
                     Description=description, Keywords="dexlabel, team",
                     QualificationTypeStatus="Active")
        type_id: str = reply["QualificationType"]["QualificationTypeId"]
        with session_scope() as session:
            session.add(CrowdQualification(name=name, qualification_type_id=type_id))
        return type_id

    def unit(self, unit_id: str) -> UnitState | None:
        """The task from the HIT's note; open until closed or expired (a unit whose places
        are all taken stays the team's open work)."""
        hit = self._hit(unit_id)
        if hit is None:
            return None
        task = _TASK_IN_NOTE.search(hit.get("RequesterAnnotation") or "")
        return UnitState(
            unit_id=unit_id, task_id=int(task.group(1)) if task else None,
            places=hit["MaxAssignments"], held=hit["NumberOfAssignmentsPending"],
            submitted=sum(1 for _ in self.submissions([unit_id])),
            allotted_s=hit["AssignmentDurationInSeconds"],
            open=hit["HITStatus"] != "Disposed" and hit["Expiration"] > datetime.now(UTC))

    def bonus_paid(self, order: BonusOrder) -> bool:
        """Never: a team bonus is paid nowhere, so the ledger's row is the whole of it."""
        return False

    def pay_bonus(self, order: BonusOrder) -> None:
        """Nothing is sent: the bonus is the ledger's row. Refuses an assignment the team
        account does not know, so a wrong id is not recorded as paid."""
        if self.submission(order.assignment_id) is None:
            raise ProviderError(f"assignment {order.assignment_id} is not a team submission",
                                "pay_bonus", "not_found")

    def training_group(self) -> str:
        return self._group(TRAINING_GROUP, "Team members who passed the dexlabel training task.")

    def completion(self, unit_id: str, assignment_id: str) -> Completion:
        """Back to the portal's list of HITs."""
        return Completion("portal", public_url(self._settings).rstrip("/") + PORTAL_HITS)


def _requirements(wanted: Requirements, granted: dict[str, str]) -> list[dict]:
    """The allow-list and the assignee's own qualification; no approval rate (ignored for
    the team) and no locales (refused by check_publish)."""
    reqs: list[dict] = []
    for type_id in (wanted.group, granted.get(wanted.assignee or "")):
        if type_id:
            reqs += qualification_requirements(Requirements(group=type_id))
    return reqs


def team_settings(settings: Settings) -> Settings:
    """``settings`` pointed at the built-in marketplace with the team account's key pair."""
    team = team_market_requester(settings.signing_key)
    return settings.model_copy(update={
        "mturk_endpoint_url": None, "mturk_use_aws": False,
        "mturk_access_key_id": team.access_key, "mturk_secret_access_key": team.secret_key})


def make(settings: Settings) -> TeamProvider:
    """The team provider of this instance."""
    return TeamProvider(team_settings(settings))
