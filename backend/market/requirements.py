"""Qualification requirements of HITs: checked when a HIT type is made, evaluated per worker.

A requirement guards an action (``ActionsGuarded``): Accept (the default), PreviewAndAccept
(``RequiredToPreview``) or DiscoverPreviewAndAccept. A worker who does not meet it cannot take
the guarded actions; a worker without the qualification meets only ``DoesNotExist``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from backend.market.errors import QUALIFICATION_TYPE_DOES_NOT_EXIST, RequestError, invalid
from backend.market.models import MarketAssignment, Qualification, QualificationType, Worker

# MTurk's system qualification types.
LOCALE = "00000000000000000071"
PERCENT_APPROVED = "000000000000000000L0"
NUMBER_APPROVED = "00000000000000000040"
ADULT = "00000000000000000060"
MASTERS = ("2F1QJWKUDD8XADTFD2Q0G6UTO95ALH", "2ARFPLSP75KLA8M8DH1HTEQVJT3SY6")
SYSTEM_TYPES = {LOCALE, PERCENT_APPROVED, NUMBER_APPROVED, ADULT, *MASTERS}

MAX_REQUIREMENTS = 10
MAX_INTEGER_VALUES = 15
MAX_LOCALE_VALUES = 30
ACTIONS = ("Discover", "Preview", "Accept")
_GUARDS = {"Accept": ("Accept",), "PreviewAndAccept": ("Preview", "Accept"),
           "DiscoverPreviewAndAccept": ACTIONS}
_ORDERED = {"LessThan", "LessThanOrEqualTo", "GreaterThan", "GreaterThanOrEqualTo"}
_SINGLE = {"EqualTo", "NotEqualTo"}
_SET = {"In", "NotIn"}
_PRESENCE = {"Exists", "DoesNotExist"}


def check_requirements(session: Session, requirements: list[dict[str, Any]]) -> None:
    """Refuse requirements MTurk would refuse: unknown types, wrong value counts or kinds."""
    if len(requirements) > MAX_REQUIREMENTS:
        raise invalid(f"QualificationRequirements may hold at most {MAX_REQUIREMENTS} entries")
    for index, req in enumerate(requirements):
        where = f"QualificationRequirements[{index}]"
        type_id = req["QualificationTypeId"]
        if type_id not in SYSTEM_TYPES:
            known = session.scalar(select(QualificationType.id).where(
                QualificationType.type_id == type_id))
            if known is None:
                raise RequestError(f"{where}: qualification type {type_id} does not exist.",
                                   QUALIFICATION_TYPE_DOES_NOT_EXIST)
        _check_values(req, where, locale=type_id == LOCALE)
        if "RequiredToPreview" in req and "ActionsGuarded" in req:
            raise invalid(f"{where}: use ActionsGuarded or RequiredToPreview, not both")


def _check_values(req: dict[str, Any], where: str, locale: bool) -> None:
    comparator = req["Comparator"]
    ints, locales = req.get("IntegerValues") or [], req.get("LocaleValues") or []
    if locale and ints:
        raise invalid(f"{where}: the Worker_Locale type takes LocaleValues, not IntegerValues")
    if not locale and locales:
        raise invalid(f"{where}: LocaleValues are only for the Worker_Locale type")
    values, limit = (locales, MAX_LOCALE_VALUES) if locale else (ints, MAX_INTEGER_VALUES)
    if comparator in _PRESENCE:
        expected = (0, 0)
    elif comparator in _SET:
        expected = (1, limit)
    elif comparator in _ORDERED and locale:
        raise invalid(f"{where}: {comparator} cannot compare locales")
    else:
        expected = (1, 1)
    if not expected[0] <= len(values) <= expected[1]:
        raise invalid(f"{where}: {comparator} takes {expected[0]} to {expected[1]} values, "
                      f"got {len(values)}")


@dataclass
class WorkerProfile:
    """What requirements are evaluated against, gathered once per worker."""

    worker_id: str
    granted: dict[str, int | None] = field(default_factory=dict)
    locale: tuple[str, str | None] | None = None
    percent_approved: int = 100
    number_approved: int = 0


def worker_profile(session: Session, worker_id: str) -> WorkerProfile:
    granted_stmt = (select(QualificationType.type_id, Qualification.integer_value)
                    .join(Qualification.qualification_type)
                    .where(Qualification.worker_id == worker_id,
                           Qualification.status == "Granted"))
    granted = dict(session.execute(granted_stmt).all())
    profile = WorkerProfile(worker_id, granted)
    worker = session.scalars(select(Worker).where(Worker.worker_id == worker_id)).one_or_none()
    if worker is not None and worker.locale_country:
        profile.locale = (worker.locale_country, worker.locale_subdivision)
    reviewed = (select(MarketAssignment.status, func.count())
                .where(MarketAssignment.worker_id == worker_id,
                       MarketAssignment.status.in_(("Approved", "Rejected")))
                .group_by(MarketAssignment.status))
    counts = dict(session.execute(reviewed).all())
    approved, rejected = counts.get("Approved", 0), counts.get("Rejected", 0)
    profile.number_approved = approved
    # A worker with no reviewed work yet has a 100% approval rate, as on MTurk.
    profile.percent_approved = 100 if approved + rejected == 0 else (
        100 * approved // (approved + rejected))
    return profile


def _value(profile: WorkerProfile, type_id: str) -> tuple[bool, Any]:
    if type_id == LOCALE:
        return profile.locale is not None, profile.locale
    if type_id == PERCENT_APPROVED:
        return True, profile.percent_approved
    if type_id == NUMBER_APPROVED:
        return True, profile.number_approved
    if type_id in profile.granted:
        return True, profile.granted[type_id]
    return False, None


def _locale_matches(have: tuple[str, str | None], want: dict[str, Any]) -> bool:
    if have[0] != want["Country"]:
        return False
    return "Subdivision" not in want or have[1] == want["Subdivision"]


def meets(profile: WorkerProfile, req: dict[str, Any]) -> bool:
    """Whether the worker satisfies one requirement."""
    comparator = req["Comparator"]
    has, value = _value(profile, req["QualificationTypeId"])
    if comparator in _PRESENCE:
        return has == (comparator == "Exists")
    if not has or value is None:
        return False
    if req["QualificationTypeId"] == LOCALE:
        hits = [_locale_matches(value, want) for want in req.get("LocaleValues", [])]
        return any(hits) if comparator in ("EqualTo", "In") else not any(hits)
    targets = req.get("IntegerValues", [])
    checks: dict[str, Callable[[], bool]] = {
        "LessThan": lambda: value < targets[0],
        "LessThanOrEqualTo": lambda: value <= targets[0],
        "GreaterThan": lambda: value > targets[0],
        "GreaterThanOrEqualTo": lambda: value >= targets[0],
        "EqualTo": lambda: value == targets[0],
        "NotEqualTo": lambda: value != targets[0],
        "In": lambda: value in targets,
        "NotIn": lambda: value not in targets,
    }
    return checks[comparator]()


def guarded_actions(req: dict[str, Any]) -> tuple[str, ...]:
    if "ActionsGuarded" in req:
        return _GUARDS[req["ActionsGuarded"]]
    return _GUARDS["PreviewAndAccept" if req.get("RequiredToPreview") else "Accept"]


def allowed_actions(profile: WorkerProfile, requirements: list[dict[str, Any]]) -> set[str]:
    """Which of Discover, Preview and Accept the worker may take on a HIT."""
    allowed = set(ACTIONS)
    for req in requirements:
        if not meets(profile, req):
            allowed -= set(guarded_actions(req))
    return allowed
