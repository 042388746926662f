"""Prolific's submissions in our words: statuses, and which unit each one took.

A submission's unit is the access detail it was sent to: Prolific records the access detail's
``external_url`` on the submission; where a submission does not carry it, our annotation page
recorded the unit when the participant opened it (the assignment whose external id is the
submission's id, Prolific's ``SESSION_ID``, and whose HIT id is the unit id).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from sqlalchemy import select

from backend.annotation.models import Assignment
from backend.crowd.provider import ProviderError, SubmissionRecord, SubmissionStatus
from backend.crowd.providers.prolific.client import ProlificClient
from backend.crowd.providers.prolific.models import ProlificStudy, ProlificUnit
from backend.crowd.providers.prolific.studies import unit_id
from backend.db import session_scope

STATUSES: dict[str, SubmissionStatus] = {
    "RESERVED": "held", "ACTIVE": "held",
    "AWAITING REVIEW": "submitted",
    "APPROVED": "approved", "REJECTED": "rejected",
    "RETURNED": "returned", "TIMED-OUT": "returned", "SCREENED OUT": "returned",
}


def our_status(prolific_status: str) -> SubmissionStatus:
    """Our status of a Prolific one; its list filter spells them with underscores too."""
    status = STATUSES.get(prolific_status.upper().replace("_", " "))
    if status is None:
        raise ProviderError(f"Prolific gave an unknown submission status {prolific_status!r}",
                            "submission")
    return status


def study_submissions(client: ProlificClient, study_id: str) -> Iterator[dict[str, Any]]:
    """Every submission of a study, page by page."""
    page: Any = client.get(f"/api/v1/studies/{study_id}/submissions/")
    while True:
        yield from page.get("results", [])
        following = (page.get("_links") or {}).get("next") or {}
        if not following.get("href"):
            return
        page = client.request("GET", following["href"])


def records(submissions: list[dict[str, Any]]) -> list[SubmissionRecord]:
    """Our records of Prolific's submissions (of any studies), with each one's unit."""
    units = _units_by_url({str(item["study_id"]) for item in submissions})
    opened = _units_by_session([str(item["id"]) for item in submissions])
    found = []
    for item in submissions:
        study = str(item["study_id"])
        unit = units.get((study, str(item.get("external_url") or "")))
        found.append(SubmissionRecord(
            assignment_id=str(item["id"]),
            unit_id=unit or opened.get(str(item["id"])) or f"{study}:",
            worker_id=str(item["participant_id"]), status=our_status(str(item["status"]))))
    return found


def _units_by_url(study_ids: set[str]) -> dict[tuple[str, str], str]:
    with session_scope() as session:
        rows = session.execute(select(ProlificStudy.study_id, ProlificUnit.external_url,
                                      ProlificUnit.position)
                               .join(ProlificUnit, ProlificUnit.study_row_id == ProlificStudy.id)
                               .where(ProlificStudy.study_id.in_(study_ids))).all()
    return {(str(study), url): unit_id(str(study), position) for study, url, position in rows}


def _units_by_session(session_ids: list[str]) -> dict[str, str]:
    with session_scope() as session:
        rows = session.execute(select(Assignment.external_id, Assignment.hit_id)
                               .where(Assignment.external_id.in_(session_ids))).all()
    return {external: hit for external, hit in rows if hit}
