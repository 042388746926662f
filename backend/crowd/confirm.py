"""The page's own submit notification: look one assignment up with its provider.

When a worker submits in our page, the provider learns of it a moment later (on MTurk the
page's form post to ``/mturk/externalSubmit``). The confirm job asks the assignment's provider
for it; until the provider lists it as submitted the job fails and is retried with backoff, so
a submission is accepted without waiting for the next ``crowd sync``.
"""

from __future__ import annotations

from sqlalchemy import select

from backend.annotation.models import Assignment
from backend.crowd.models import CrowdSubmission
from backend.crowd.provider import COLLECTED, SubmissionRecord
from backend.crowd.providers import get_provider
from backend.db import session_scope
from backend.jobs.runner import RetryLater


class NotSubmittedYet(RetryLater):
    """The provider has not recorded the submission yet (the job retries later)."""


def submitted_record(assignment_id: int) -> SubmissionRecord | str:
    """The provider's record of our submitted assignment, or why there is none to accept
    ("assignment deleted", "not from a marketplace", "already_accepted").

    Raises NotSubmittedYet while the provider has not recorded the submission.
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
        external_id, provider = ours.external_id, ours.provider
    # MTurk lists an assignment to its requester only once it is submitted.
    record = get_provider(provider).submission(external_id)
    if record is None:
        raise NotSubmittedYet(f"assignment {external_id} is not submitted on the marketplace "
                              "yet")
    if record.status not in COLLECTED:
        raise NotSubmittedYet(f"assignment {external_id} is {record.status} on the "
                              "marketplace, not submitted yet")
    return record
