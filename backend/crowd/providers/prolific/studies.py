"""Publishing a batch of units as one Prolific Taskflow study.

Prolific rate-limits launching many small studies and points large projects to Taskflow: one
study whose ``access_details`` hold one external URL per unit of work, each with its own
allocation of places. So a publish of any number of units is one study; a unit's id is
"<study_id>:<position>" (its access detail's place in the list).

The publish goes in steps, each recorded in ``prolific_studies`` before the next call: the row
and its units (committed before anything is sent), the study created (draft), our completion
code patched on, the study published. A run that stopped anywhere (a lost reply, a crash)
resumes from the recorded step; a draft whose creation reply was lost is found again by its
``internal_name`` before another is made, so a batch never becomes two studies.
"""

from __future__ import annotations

import hashlib
import math
import secrets
from collections.abc import Sequence
from typing import Any

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError

from backend.config import Settings
from backend.crowd.provider import ProviderError, ProviderRefused, PublishedUnit, UnitSpec
from backend.crowd.providers.prolific.client import ProlificClient
from backend.crowd.providers.prolific.groups import study_filters
from backend.crowd.providers.prolific.models import ProlificStudy, ProlificUnit
from backend.db import session_scope

STUDIES = "/api/v1/studies/"
# What Prolific puts into each unit's URL: who, in which study, in which submission.
URL_PARAMETERS = "PROLIFIC_PID={%PROLIFIC_PID%}&STUDY_ID={%STUDY_ID%}&SESSION_ID={%SESSION_ID%}"


def unit_id(study_id: str, position: int) -> str:
    return f"{study_id}:{position}"


def split_unit_id(value: str) -> tuple[str, int]:
    """(study id, position) of a unit id; ProviderError not_found for anything else."""
    study, _, position = value.rpartition(":")
    if not study or not position.isdigit():
        raise ProviderError(f"{value!r} is not a Prolific unit id (<study_id>:<position>)",
                            "unit", "not_found")
    return study, int(position)


def external_url(page_url: str) -> str:
    return f"{page_url}{'&' if '?' in page_url else '?'}{URL_PARAMETERS}"


def check_units(units: Sequence[UnitSpec], settings: Settings) -> None:
    """Refuse, before any call, what one study cannot take: rewards that differ (a study pays
    one reward) and a reward under the pay floor for the unit's expected time."""
    if not units:
        return
    if len({unit.reward_cents for unit in units}) > 1:
        raise ProviderRefused(
            "a Prolific study pays one reward to every participant; publish units with "
            "different rewards separately", "publish",
            fields=[{"field": "reward", "message": "differs between units"}])
    rate, currency = settings.prolific_min_hourly_rate, settings.prolific_currency
    for unit in units:
        if unit.expected_s <= 0:
            raise ProviderRefused(f"task {unit.task_id} has no expected working time; "
                                  "Prolific's pay floor needs one", "publish",
                                  fields=[{"field": "expected_s", "message": "must be above 0"}])
        hourly = unit.reward_cents / 100 * 3600 / unit.expected_s
        if hourly + 1e-9 < rate:
            message = (f"a reward of {currency} {unit.reward_cents / 100:.2f} for "
                       f"{unit.expected_s} s of expected work pays {currency} {hourly:.2f} an "
                       f"hour, under Prolific's minimum hourly rate of {currency} {rate:.2f} "
                       "(DEXLABEL_PROLIFIC_MIN_HOURLY_RATE); at least "
                       f"{currency} {math.ceil(rate * unit.expected_s / 36) / 100:.2f}")
            raise ProviderRefused(message, "publish",
                                  fields=[{"field": "reward", "message": message}])


def batch_key(keys: Sequence[str]) -> str:
    return hashlib.sha256("\n".join(sorted(keys)).encode()).hexdigest()


def publish_units(client: ProlificClient, settings: Settings,
                  units: Sequence[UnitSpec]) -> list[PublishedUnit]:
    """Publish ``units`` as one study (resuming any earlier run of the same units)."""
    check_units(units, settings)
    rows = _recorded(units)
    fresh = [unit for unit in units if unit.key not in rows]
    made: int | None = None
    if fresh:
        made = _record_batch(fresh)
        rows.update(_recorded(fresh))
    for study_row in sorted({row for row, _ in rows.values()}):
        _finish(client, settings, study_row, units)
    with session_scope() as session:
        ids = {row.id: row.study_id for row in session.scalars(
            select(ProlificStudy).where(ProlificStudy.id.in_({r for r, _ in rows.values()})))}
    return [PublishedUnit(unit.key, unit_id(str(ids[rows[unit.key][0]]), rows[unit.key][1]),
                          "created" if rows[unit.key][0] == made else "recovered")
            for unit in units]


def _recorded(units: Sequence[UnitSpec]) -> dict[str, tuple[int, int]]:
    """key -> (study row, position) of the units already recorded."""
    keys = [unit.key for unit in units]
    with session_scope() as session:
        found = session.execute(select(ProlificUnit.key, ProlificUnit.study_row_id,
                                       ProlificUnit.position)
                                .where(ProlificUnit.key.in_(keys))).all()
    return {key: (row, position) for key, row, position in found}


def _record_batch(units: Sequence[UnitSpec]) -> int | None:
    """Write the study's row and its units (committed); the row's id, or None where a
    concurrent run of the same batch wrote it first (its row is then found by the keys)."""
    batch = batch_key([unit.key for unit in units])
    try:
        with session_scope() as session:
            study = ProlificStudy(batch_key=batch, internal_name=f"dexlabel-{batch[:32]}",
                                  state="creating",
                                  completion_code=secrets.token_hex(4).upper(),
                                  reward_cents=units[0].reward_cents,
                                  allotted_s=max(unit.allotted_s for unit in units))
            session.add(study)
            session.flush()
            session.add_all(ProlificUnit(study_row_id=study.id, key=unit.key, position=i,
                                         task_id=unit.task_id, places=unit.places,
                                         external_url=external_url(unit.page_url),
                                         place_keys=[])
                            for i, unit in enumerate(units))
            session.flush()
            return study.id
    except IntegrityError:
        return None


def _finish(client: ProlificClient, settings: Settings, row_id: int,
            units: Sequence[UnitSpec]) -> None:
    """Take the study's publish from its recorded step to the end."""
    with session_scope() as session:
        study = session.get_one(ProlificStudy, row_id)
        state, name, code = study.state, study.internal_name, study.completion_code
    if state == "creating":
        study_id = _find_draft(client, name) or _create(client, settings, row_id, units)
        _advance(row_id, "created", study_id=study_id)
        state = "created"
    study_id = _study_id(row_id)
    if state == "created":
        client.patch(f"{STUDIES}{study_id}/", {"completion_codes": [
            {"code": code, "code_type": "COMPLETED",
             "actions": [{"action": "MANUALLY_REVIEW"}]}]})
        _advance(row_id, "coded")
        state = "coded"
    if state == "coded":
        status = client.get(f"{STUDIES}{study_id}/").get("status")
        if status == "UNPUBLISHED":
            status = client.post(f"{STUDIES}{study_id}/transition/",
                                 {"action": "PUBLISH"}).get("status")
        _advance(row_id, "published", status=status)


def _find_draft(client: ProlificClient, internal_name: str) -> str | None:
    """A draft study of ours made by a run whose reply was lost, by its internal name."""
    page: Any = client.get(STUDIES, state="UNPUBLISHED")
    while True:
        for study in page.get("results", []):
            if study.get("internal_name") == internal_name:
                return str(study["id"])
        following = (page.get("_links") or {}).get("next") or {}
        if not following.get("href"):
            return None
        page = client.request("GET", following["href"])


def _create(client: ProlificClient, settings: Settings, row_id: int,
            units: Sequence[UnitSpec]) -> str:
    with session_scope() as session:
        study = session.get_one(ProlificStudy, row_id)
        recorded = list(session.scalars(select(ProlificUnit)
                                        .where(ProlificUnit.study_row_id == row_id)
                                        .order_by(ProlificUnit.position)))
        name, reward, allotted_s = study.internal_name, study.reward_cents, study.allotted_s
        access: list[dict[str, Any]] = [
            {"external_url": unit.external_url, "total_allocation": unit.places}
            for unit in recorded]
    first = units[0]
    body = {
        "name": first.title, "internal_name": name, "description": first.description,
        "access_details": access, "prolific_id_option": "url_parameters",
        "total_available_places": sum(unit.places for unit in recorded),
        "reward": reward,
        "estimated_completion_time": max(1, math.ceil(max(u.expected_s for u in units) / 60)),
        "maximum_allowed_time": max(1, math.ceil(allotted_s / 60)),
        "device_compatibility": ["desktop"],
        "filters": study_filters(client, settings, first.requirements),
    }
    return str(client.post(STUDIES, body)["id"])


def _advance(row_id: int, state: str, **values: Any) -> None:
    with session_scope() as session:
        study = session.get_one(ProlificStudy, row_id)
        study.state = state
        for name, value in values.items():
            setattr(study, name, value)


def _study_id(row_id: int) -> str:
    with session_scope() as session:
        return str(session.get_one(ProlificStudy, row_id).study_id)
