"""Before the annotation page opens a marketplace assignment: does the provider know it?

The page learns its assignment from its address (MTurk's ``assignmentId``, ``hitId`` and
``workerId``), which anyone can type. So the first time an assignment is opened, the provider
is asked (``unit`` and ``submission``; MTurk's requester API below):

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

from collections.abc import Callable
from typing import NamedTuple, TypeVar

from sqlalchemy import select

from backend.crowd.models import CrowdHit
from backend.crowd.provider import CrowdProvider, ProviderUnreachable
from backend.crowd.providers import get_provider
from backend.db import session_scope
from backend.errors import DexlabelError, Forbidden, NotFound

# How long a page should wait before asking again when the marketplace did not answer.
RETRY_AFTER_S = 30
_T = TypeVar("_T")


class MarketplaceDown(DexlabelError):
    """The marketplace did not answer, so the assignment cannot be confirmed now (503)."""

    status_code = 503
    code = "marketplace_unavailable"

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.headers = {"Retry-After": str(RETRY_AFTER_S)}


def _ask(question: Callable[[], _T]) -> _T:
    """The provider's answer; MarketplaceDown (503) when it did not answer."""
    try:
        return question()
    except ProviderUnreachable as exc:
        raise MarketplaceDown(f"the assignment cannot be checked with the marketplace now: "
                              f"{exc.detail}") from exc


def provider_of_unit(unit_id: str) -> CrowdProvider:
    """The provider that published ``unit_id`` (a unit we did not publish: the setting's)."""
    with session_scope() as session:
        name = session.scalar(select(CrowdHit.provider).where(CrowdHit.hit_id == unit_id))
    return get_provider(name)


class HeldSlots(NamedTuple):
    """A HIT's assignments held by workers and not yet submitted, as the marketplace counts
    them, and how long a worker may hold one (after that the marketplace takes it back)."""

    held: int
    duration_s: int


def confirm_held(task_id: int, hit_id: str, assignment_id: str, worker_id: str,
                 crowd: CrowdProvider | None = None) -> HeldSlots | None:
    """Returns when the provider (``crowd``, else the unit's) vouches, as far as it can,
    that ``worker_id`` holds ``assignment_id`` of ``hit_id``, a unit showing task
    ``task_id``: None when it names the assignment's worker, else the unit's held places,
    which bound how many assignments of it may be opened (the caller counts those already
    opened).

    Raises:
        NotFound: the provider has no such unit.
        Forbidden: the unit shows another page, the assignment is another unit's or
            worker's, or nobody holds a place of the unit.
        MarketplaceDown: the provider did not answer (503, Retry-After).
    """
    provider = crowd or provider_of_unit(hit_id)
    unit = _ask(lambda: provider.unit(hit_id))
    if unit is None:
        raise NotFound(f"the marketplace has no HIT {hit_id}")
    if unit.task_id != task_id:
        raise Forbidden(f"HIT {hit_id} is not a HIT of this task")
    record = _ask(lambda: provider.submission(assignment_id))
    if record is not None:
        if record.unit_id != hit_id or record.worker_id != worker_id:
            raise Forbidden(f"the marketplace's assignment {assignment_id} is not worker "
                            f"{worker_id}'s on HIT {hit_id}")
        return None
    if unit.held < 1:
        raise Forbidden(f"the marketplace knows no assignment {assignment_id}: no worker holds "
                        f"an assignment of HIT {hit_id} (accept the HIT first)")
    return HeldSlots(unit.held, unit.allotted_s)
