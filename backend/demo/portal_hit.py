"""A hand HIT left open in the worker portal, so a newcomer signed in as the demo worker can
try the hand task as a worker does (the simulated crowd takes every hand assignment first,
since hand tasks are published first, and would leave only object HITs there)."""

from __future__ import annotations

import typer
from sqlalchemy import select

from backend.db import session_scope
from backend.demo import DEMO_WORKER_EMAIL


def _demo_worker_id() -> str | None:
    from backend.accounts.models import PortalAccount

    with session_scope() as session:
        return session.scalar(select(PortalAccount.worker_id).where(
            PortalAccount.email == DEMO_WORKER_EMAIL))


def _hand_hits(sequence_id: int) -> list[tuple[str, int]]:
    """The sequence's published hand HITs, first published first: (HIT id, its places)."""
    from backend.annotation.models import Task
    from backend.crowd.models import CrowdHit

    with session_scope() as session:
        rows = session.execute(
            select(CrowdHit.hit_id, CrowdHit.max_assignments)
            .join(Task, Task.id == CrowdHit.task_id)
            .where(Task.sequence_id == sequence_id, Task.kind == "hand",
                   CrowdHit.hit_id.is_not(None), CrowdHit.expired_at.is_(None))
            .order_by(CrowdHit.id)).all()
    return [(str(hit_id), int(places)) for hit_id, places in rows]


def _takeable(worker_id: str) -> set[str]:
    """The HITs the worker's portal list offers to accept now."""
    from backend.market.clock import now
    from backend.portal.service import list_hits

    with session_scope() as session:
        return {view.hit.hit_id for view in list_hits(session, worker_id, now())
                if view.can_accept}


def leave_hand_hit(sequence_id: int) -> str | None:
    """A hand HIT the demo worker can accept in the portal: one already open, else the first
    hand HIT with one more place (where the HIT stays under the large-HIT rule). The HIT id;
    None when the sequence has no hand HIT to offer."""
    from backend.crowd.actions import add_assignments
    from backend.crowd.providers import get_provider

    marketplace = get_provider("mturk")
    large = marketplace.fees().large_unit_places

    worker_id = _demo_worker_id()
    hands = _hand_hits(sequence_id)
    if worker_id is None or not hands:
        return None
    open_now = _takeable(worker_id)
    hit_id = next((h for h, _ in hands if h in open_now), None)
    if hit_id is None:
        hit_id = next((h for h, places in hands if places + 1 < large), None)
        if hit_id is None:
            return None
        with session_scope() as session, session.no_autoflush:
            add_assignments(session, marketplace, hit_id, 1)
    typer.echo(f"hand HIT {hit_id} is open in the worker portal for the demo worker")
    return hit_id
