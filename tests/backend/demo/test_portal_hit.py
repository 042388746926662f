"""After the demo's crowd has taken every hand assignment, the demo still leaves a hand HIT
that its worker can accept in the portal (the portal's own HIT list, as the demo worker signed
in sees it); a re-run leaves the same HIT and adds no place."""

from __future__ import annotations

import httpx
from sqlalchemy import select

from backend.db import session_scope
from tests.backend.crowd.conftest import crowd_url, market_env
from tests.backend.market.conftest import market_database_url, market_url, migrated_sqlite
from tests.backend.market.helpers import accept

__all__ = ["crowd_url", "market_database_url", "market_env", "market_url", "migrated_sqlite"]


def _portal_hits(base: str, email: str, password: str) -> dict[str, dict]:
    """The demo worker's HIT list in the portal: {HIT id: the listed HIT}."""
    login = httpx.post(f"{base}/api/portal/login", timeout=30,
                       json={"email": email, "password": password})
    assert login.status_code == 200, login.text
    hits = httpx.get(f"{base}/api/portal/hits?mine=true", timeout=30,
                     headers={"Authorization": f"Bearer {login.json()['access_token']}"})
    assert hits.status_code == 200, hits.text
    return {hit["hit_id"]: hit for hit in hits.json()}


def _places(hit_id: str) -> int:
    from backend.crowd.models import CrowdHit

    with session_scope() as session:
        return int(session.scalars(select(CrowdHit.max_assignments).where(
            CrowdHit.hit_id == hit_id)).one())


def test_the_demo_leaves_a_hand_hit_in_the_portal_for_its_worker(crowd_url: str) -> None:
    from backend.annotation.models import Task
    from backend.config import get_settings
    from backend.crowd import flows
    from backend.crowd.client import make_client
    from backend.crowd.schemas import PublishOptions
    from backend.demo import demo_logins
    from backend.demo.portal_hit import leave_hand_hit
    from tests.backend.crowd.helpers import make_tasks

    task_ids = make_tasks(2)
    with session_scope() as session:
        sequence_id = session.get_one(Task, task_ids[0]).sequence_id
    worker = demo_logins()["worker"]
    published = flows.publish_each(make_client(get_settings()), PublishOptions(
        max_assignments=1, min_approval_rate=None), sequence_id, "hand")
    hand_hits = published.hit_ids
    assert len(hand_hits) == 2
    # The simulated crowd takes every hand assignment.
    for n, hit_id in enumerate(hand_hits):
        accept(hit_id, f"ASIMULATEDHAND{n}")
    assert not set(_portal_hits(crowd_url, worker.email, worker.password)) & set(hand_hits)

    left = leave_hand_hit(sequence_id)
    assert left == hand_hits[0] and _places(left) == 2
    listed = _portal_hits(crowd_url, worker.email, worker.password)
    assert left in listed and "hand" in listed[left]["task"]["target"]
    assert listed[left]["available"] == 1

    assert leave_hand_hit(sequence_id) == left  # a re-run: already open, no place added
    assert _places(left) == 2
