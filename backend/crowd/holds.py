"""Before the annotation page opens a marketplace assignment: does the marketplace know it?

The page learns its assignment from its address (MTurk's ``assignmentId``, ``hitId`` and
``workerId``), which anyone can type. So the first time an assignment is opened, the requester
API is asked:

- GetHIT: the HIT exists for this requester and its page (the ExternalQuestion's URL) is this
  task's page, with a task token for this task;
- GetAssignment: once the marketplace shows the assignment (MTurk shows an assignment to its
  requester only after it is submitted), it must be of that HIT and that worker, in any status;
- until then the HIT must count an assignment as held by a worker (NumberOfAssignmentsPending):
  an assignment id is not taken on trust when nobody holds one of the HIT.

The requester API cannot name the worker of an assignment that is held but not yet submitted,
so the worker and assignment of such a start are confirmed when the work is submitted (the
confirm job, ``backend.crowd.confirm``), and only confirmed marketplace work is scored.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any, NamedTuple
from urllib.parse import parse_qs, urlsplit

from backend.annotation.tokens import TASK_SCOPE
from backend.config import get_settings
from backend.crowd.client import (
    MarketplaceError,
    MarketplaceUnreachable,
    MTurkClient,
    call,
    make_client,
)
from backend.errors import DexlabelError, Forbidden, NotFound, Unauthorized
from backend.security import verify_token

# How long a page should wait before asking again when the marketplace did not answer.
RETRY_AFTER_S = 30


class MarketplaceDown(DexlabelError):
    """The marketplace did not answer, so the assignment cannot be confirmed now (503)."""

    status_code = 503
    code = "marketplace_unavailable"

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.headers = {"Retry-After": str(RETRY_AFTER_S)}


def _missing(exc: MarketplaceError) -> bool:
    return "DoesNotExist" in exc.turk_code or "does not exist" in exc.detail


def _ask(client: MTurkClient, operation: str, **params: Any) -> dict[str, Any] | None:
    """The reply of ``operation``; None when the marketplace says the record does not exist."""
    try:
        return call(client, operation, **params)
    except MarketplaceUnreachable as exc:
        raise MarketplaceDown(f"the assignment cannot be checked with the marketplace now: "
                              f"{exc.detail}") from exc
    except MarketplaceError as exc:
        if _missing(exc):
            return None
        raise


def task_of_question(question: str) -> int | None:
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
        claims = verify_token(tokens[0], get_settings().signing_key, TASK_SCOPE)
    except Unauthorized:
        return None
    return int(claims["task_id"])


class HeldSlots(NamedTuple):
    """A HIT's assignments held by workers and not yet submitted, as the marketplace counts
    them, and how long a worker may hold one (after that the marketplace takes it back)."""

    held: int
    duration_s: int


def confirm_held(task_id: int, hit_id: str, assignment_id: str,
                 worker_id: str) -> HeldSlots | None:
    """Returns when the marketplace vouches, as far as its requester API can, that
    ``worker_id`` holds ``assignment_id`` of ``hit_id``, a HIT showing task ``task_id``:
    None when it names the assignment's worker, else the HIT's held slots, which bound how
    many assignments of it may be opened (the caller counts those already opened).

    Raises:
        NotFound: the marketplace has no such HIT.
        Forbidden: the HIT shows another page, the assignment is another HIT's or worker's,
            or nobody holds an assignment of the HIT.
        MarketplaceDown: the marketplace did not answer (503, Retry-After).
    """
    client = make_client(get_settings())
    reply = _ask(client, "get_hit", HITId=hit_id)
    if reply is None:
        raise NotFound(f"the marketplace has no HIT {hit_id}")
    hit = reply["HIT"]
    if task_of_question(str(hit.get("Question", ""))) != task_id:
        raise Forbidden(f"HIT {hit_id} is not a HIT of this task")
    found = _ask(client, "get_assignment", AssignmentId=assignment_id)
    if found is not None:
        record = found["Assignment"]
        if record.get("HITId") != hit_id or record.get("WorkerId") != worker_id:
            raise Forbidden(f"the marketplace's assignment {assignment_id} is not worker "
                            f"{worker_id}'s on HIT {hit_id}")
        return None
    held = int(hit.get("NumberOfAssignmentsPending") or 0)
    if held < 1:
        raise Forbidden(f"the marketplace knows no assignment {assignment_id}: no worker holds "
                        f"an assignment of HIT {hit_id} (accept the HIT first)")
    return HeldSlots(held, int(hit.get("AssignmentDurationInSeconds") or 0))
