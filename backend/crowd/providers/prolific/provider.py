"""``ProlificProvider``: the CrowdProvider protocol onto Prolific's public API.

What Prolific allows and how each of our verbs maps onto it:

- publish: one Taskflow study per batch (``studies``); check_publish refuses a reward under
  the pay floor before any call.
- review: ``POST /api/v1/submissions/{id}/transition/`` with APPROVE or REJECT; a rejection
  needs a message of at least 100 characters and one of Prolific's rejection categories,
  both checked before any call.
- bonuses: ``bonuses`` (set up, then pay once, one at a time).
- the unit's life: after publishing, a study's ``internal_name`` and
  ``total_available_places`` are all that may change, and places only go up. add_places
  raises the study's places (the unit's count kept here; the total sent is our sum, so a
  repeat sends the same number). close cannot take places back nor close one access detail:
  the unit is closed here (``unit()`` says so, our page turns new participants away) and the
  study is stopped once every unit of it is closed. extend is refused: a Prolific study has
  no expiry to extend (it runs until its places are taken or it is stopped), and the time one
  participant may hold a unit is fixed at publish.
- who may take work: participant groups (``groups``); messages to participants.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.config import Settings
from backend.crowd.provider import (
    BonusOrder,
    Completion,
    FeeSchedule,
    ProviderError,
    ProviderName,
    ProviderRefused,
    PublishedUnit,
    SubmissionRecord,
    SubmissionStatus,
    UnitSpec,
    UnitState,
    decided_already,
)
from backend.crowd.providers.prolific import bonuses, groups, studies, submissions
from backend.crowd.providers.prolific.client import ProlificClient
from backend.crowd.providers.prolific.models import ProlificStudy, ProlificUnit
from backend.db import session_scope, utcnow

COMPLETE_URL = "https://app.prolific.com/submissions/complete?cc="
MIN_REJECTION_MESSAGE = 100
# Prolific's rejection categories (docs.prolific.com, "Approve or reject a submission").
REJECTION_CATEGORIES = ("TOO_QUICKLY", "TOO_SLOWLY", "FAILED_INSTRUCTIONS",
                        "INCOMP_LONGITUDINAL", "FAILED_CHECK", "LOW_EFFORT", "MALINGERING",
                        "NO_CODE", "BAD_CODE", "NO_DATA", "UNSUPP_DEVICE", "OTHER")


class ProlificProvider:
    """One Prolific workspace, as the settings name it."""

    name: ProviderName = "prolific"

    def __init__(self, settings: Settings, client: ProlificClient | None = None) -> None:
        self.settings = settings
        self.client = client or ProlificClient.from_settings(settings)

    def fees(self) -> FeeSchedule:
        rate = self.settings.prolific_fee_rate
        return FeeSchedule(provider="prolific", currency=self.settings.prolific_currency,
                           reward_rate=rate, large_unit_rate=rate, large_unit_places=0,
                           bonus_rate=rate, min_fee_cents=0)

    # ----- publishing ----------------------------------------------------------------------

    def check_publish(self, units: Sequence[UnitSpec]) -> None:
        studies.check_units(units, self.settings)

    def publish(self, units: Sequence[UnitSpec]) -> list[PublishedUnit]:
        return studies.publish_units(self.client, self.settings, units)

    def unit(self, unit_id: str) -> UnitState | None:
        study_id, position = studies.split_unit_id(unit_id)
        with session_scope() as session:
            row = _unit_row(session, study_id, position)
            if row is None:
                return None
            task_id, places, closed = row[0].task_id, row[0].places, row[0].closed_at
            allotted_s = row[1].allotted_s
        study = self.client.get(f"{studies.STUDIES}{study_id}/")
        taken = [record for record in self.submissions_of(study_id)
                 if record.unit_id == unit_id]
        held = sum(record.status == "held" for record in taken)
        submitted = sum(record.status == "submitted" for record in taken)
        active = [r for r in taken if r.status != "returned"]
        is_open = (closed is None and study.get("status") == "ACTIVE"
                   and len(active) < places)
        return UnitState(unit_id=unit_id, task_id=task_id, places=places, held=held,
                         submitted=submitted, allotted_s=allotted_s, open=is_open)

    # ----- submissions ---------------------------------------------------------------------

    def submissions_of(self, study_id: str) -> list[SubmissionRecord]:
        """Every submission of a study, whatever its status."""
        return submissions.records(list(submissions.study_submissions(self.client, study_id)))

    def submissions(self, unit_ids: Sequence[str]) -> Iterator[SubmissionRecord]:
        wanted = set(unit_ids)
        for study_id in sorted({studies.split_unit_id(u)[0] for u in unit_ids}):
            for record in self.submissions_of(study_id):
                if record.unit_id in wanted and record.status in ("submitted", "approved",
                                                                  "rejected"):
                    yield record

    def submission(self, assignment_id: str) -> SubmissionRecord | None:
        try:
            item = self.client.get(f"/api/v1/submissions/{assignment_id}/")
        except ProviderError as exc:
            if exc.reason == "not_found":
                return None
            raise
        return submissions.records([item])[0]

    # ----- decisions -----------------------------------------------------------------------

    def approve(self, assignment_id: str, feedback: str | None) -> None:
        """Approve (Prolific's approval carries no message: feedback goes as a message)."""
        self._transition(assignment_id, {"action": "APPROVE"}, "approved")
        if feedback:
            record = self.submission(assignment_id)
            if record is not None:
                groups.send_messages(self.client, [record.worker_id], "Your submission",
                                     feedback)

    def reject(self, assignment_id: str, feedback: str, category: str | None) -> None:
        check_rejection(feedback, category)
        self._transition(assignment_id, {"action": "REJECT", "message": feedback.strip(),
                                         "rejection_category": category}, "rejected")

    def _transition(self, assignment_id: str, body: dict[str, str | None],
                    done: SubmissionStatus) -> None:
        try:
            self.client.post(f"/api/v1/submissions/{assignment_id}/transition/", body)
        except ProviderError as exc:
            if not decided_already(self, exc, assignment_id, done):
                raise

    def bonus_paid(self, order: BonusOrder) -> bool:
        return bonuses.bonus_paid(self.client, order)

    def pay_bonus(self, order: BonusOrder) -> None:
        study_id = studies.split_unit_id(order.unit_id)[0]
        bonuses.pay_bonus(self.client, order, study_id)

    # ----- the unit's life -----------------------------------------------------------------

    def extend(self, unit_id: str, seconds: int) -> None:
        raise ProviderRefused(
            "a Prolific study has no expiry to extend: it stays open until its places are "
            "taken or it is stopped, and the time one participant may hold a unit is fixed "
            "when it is published; add places instead", "extend",
            fields=[{"field": "seconds", "message": "Prolific has no expiry"}])

    def close(self, unit_id: str) -> None:
        study_id, position = studies.split_unit_id(unit_id)
        with session_scope() as session:
            row = _unit_row(session, study_id, position)
            if row is None:
                raise ProviderError(f"no Prolific unit {unit_id}", "close", "not_found")
            if row[0].closed_at is None:
                row[0].closed_at = utcnow()
            open_left = session.scalar(select(ProlificUnit.id).where(
                ProlificUnit.study_row_id == row[1].id, ProlificUnit.closed_at.is_(None)))
        if open_left is None:
            status = self.client.get(f"{studies.STUDIES}{study_id}/").get("status")
            if status in ("ACTIVE", "PAUSED"):
                self.client.post(f"{studies.STUDIES}{study_id}/transition/",
                                 {"action": "STOP"})

    def add_places(self, unit_id: str, count: int, key: str) -> None:
        if count < 1:
            raise ProviderRefused("places can only be added (Prolific never takes them back)",
                                  "add_places", fields=[{"field": "count",
                                                         "message": "must be 1 or more"}])
        study_id, position = studies.split_unit_id(unit_id)
        with session_scope() as session:
            row = _unit_row(session, study_id, position)
            if row is None:
                raise ProviderError(f"no Prolific unit {unit_id}", "add_places", "not_found")
            unit, study = row
            if key not in unit.place_keys:
                unit.places += count
                unit.place_keys = [*unit.place_keys, key]
            session.flush()
            total = sum(session.scalars(select(ProlificUnit.places)
                                        .where(ProlificUnit.study_row_id == study.id)))
        self.client.patch(f"{studies.STUDIES}{study_id}/", {"total_available_places": total})

    # ----- workers -------------------------------------------------------------------------

    def block(self, worker_id: str, reason: str) -> None:
        group = groups.ensure_group(self.client, self.settings, groups.BLOCKED_GROUP)
        groups.add_member(self.client, group, worker_id)

    def unblock(self, worker_id: str, reason: str | None) -> None:
        group = groups.find_group(self.client, self.settings, groups.BLOCKED_GROUP)
        if group is not None:
            groups.remove_member(self.client, group, worker_id)

    def training_group(self) -> str:
        return groups.ensure_group(self.client, self.settings, groups.TRAINING_GROUP)

    def grant(self, worker_id: str, group: str, value: int, notify: bool) -> None:
        groups.add_member(self.client, group, worker_id)
        if notify:
            groups.send_messages(self.client, [worker_id], "You may take more of our work",
                                 "You passed our training: our studies for trained "
                                 "participants are open to you now.")

    def revoke(self, worker_id: str, group: str, reason: str | None) -> None:
        groups.remove_member(self.client, group, worker_id)

    def notify(self, worker_ids: Sequence[str], subject: str,
               message: str) -> list[dict[str, str]]:
        return groups.send_messages(self.client, worker_ids, subject, message)

    def completion(self, unit_id: str, assignment_id: str) -> Completion:
        study_id, _ = studies.split_unit_id(unit_id)
        with session_scope() as session:
            code = session.scalar(select(ProlificStudy.completion_code)
                                  .where(ProlificStudy.study_id == study_id))
        if code is None:
            raise ProviderError(f"no Prolific study {study_id} of ours", "completion",
                                "not_found")
        return Completion("redirect", f"{COMPLETE_URL}{code}")


def check_rejection(feedback: str, category: str | None) -> None:
    """Prolific's rules for a rejection, checked before any call: ProviderRefused naming the
    field."""
    length = len(feedback.strip())
    if length < MIN_REJECTION_MESSAGE:
        raise ProviderRefused(
            f"Prolific needs a rejection message of at least {MIN_REJECTION_MESSAGE} "
            f"characters telling the participant why; this one has {length}", "reject",
            fields=[{"field": "feedback",
                     "message": f"at least {MIN_REJECTION_MESSAGE} characters"}])
    if category not in REJECTION_CATEGORIES:
        raise ProviderRefused(
            f"Prolific needs a rejection category, one of {', '.join(REJECTION_CATEGORIES)}; "
            f"got {category!r}", "reject",
            fields=[{"field": "category", "message": "one of Prolific's categories"}])


def _unit_row(session: Session, study_id: str,
              position: int) -> tuple[ProlificUnit, ProlificStudy] | None:
    """Our rows of one unit and its study."""
    found = session.execute(select(ProlificUnit, ProlificStudy)
                            .join(ProlificStudy, ProlificUnit.study_row_id == ProlificStudy.id)
                            .where(ProlificStudy.study_id == study_id,
                                   ProlificUnit.position == position)).first()
    return None if found is None else (found[0], found[1])
