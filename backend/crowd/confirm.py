"""The page's own submit notification: look one assignment up with the requester API.

When a worker submits in our page, the marketplace learns of it a moment later (the page's
form post to ``/mturk/externalSubmit``). The confirm job asks the requester API for that
assignment; until the marketplace lists it as submitted the job fails and is retried with
backoff, so a submission is accepted without waiting for the next ``crowd sync``.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import select

from backend.annotation.models import Assignment
from backend.config import get_settings
from backend.crowd.client import MarketplaceError, call, make_client
from backend.crowd.models import CrowdSubmission
from backend.crowd.sync import COLLECTED_STATUSES
from backend.db import session_scope
from backend.jobs.runner import RetryLater


class NotSubmittedYet(RetryLater):
    """The marketplace has not recorded the submission yet (the job retries later)."""


def submitted_record(assignment_id: int) -> dict[str, Any] | str:
    """The requester API's record of our submitted assignment, or why there is none to
    accept ("assignment deleted", "not from a marketplace", "already_accepted").

    Raises NotSubmittedYet while the marketplace has not recorded the submission.
    """
    with session_scope() as session:
        ours = session.get(Assignment, assignment_id)
        if ours is None:
            return "assignment deleted"
        if ours.hit_id is None:
            return "not from a marketplace"
        if session.scalar(select(CrowdSubmission.id).where(
                CrowdSubmission.assignment_id == assignment_id)) is not None:
            return "already_accepted"
        external_id = ours.external_id
    try:
        reply = call(make_client(get_settings()), "get_assignment", AssignmentId=external_id)
    except MarketplaceError as exc:
        # The requester API lists an assignment only once it is submitted, as MTurk does.
        if "does not exist" not in exc.detail:
            raise
        raise NotSubmittedYet(f"assignment {external_id} is not submitted on the marketplace "
                              "yet") from exc
    record: dict[str, Any] = reply["Assignment"]
    if record["AssignmentStatus"] not in COLLECTED_STATUSES:
        raise NotSubmittedYet(f"assignment {external_id} is {record['AssignmentStatus']} on "
                              "the marketplace, not submitted yet")
    return record
