"""Helpers of the crowd tests: a minimal sequence with tasks, and a worker's submission."""

from __future__ import annotations

import uuid
from typing import Any

from backend.db import session_scope

ADMIN_EMAIL = "crowd-admin@example.org"
ADMIN_PASSWORD = "correct horse battery"


def make_tasks(views: int, sequence_name: str = "grasp") -> list[int]:
    """One sequence with ``views`` cameras and a hand task per view, straight in the DB."""
    from backend.annotation.models import Task
    from backend.captures.models import Camera, Sequence, Subject

    with session_scope() as session:
        subject = Subject(name=f"subject-{uuid.uuid4().hex[:6]}")
        sequence = Sequence(subject=subject, name=sequence_name, storage_uid=uuid.uuid4().hex,
                            num_frames=6, source_kind="images", fingerprint="0" * 64)
        session.add(sequence)
        session.flush()
        ids = []
        for view in range(views):
            camera = Camera(sequence_id=sequence.id, serial=f"cam{view}", view_index=view,
                            width=640, height=480, fx=600.0, fy=600.0, ppx=320.0, ppy=240.0,
                            distortion=[0.0] * 5, extrinsics=[[1, 0, 0, 0], [0, 1, 0, 0],
                                                             [0, 0, 1, 0]])
            session.add(camera)
            session.flush()
            task = Task(sequence_id=sequence.id, camera_id=camera.id, kind="hand",
                        target_key="hand:0", num_points=21)
            session.add(task)
            session.flush()
            ids.append(task.id)
        return ids


def worker_submits(base: str, hit_id: str, worker_id: str,
                   page_worker_id: str | None = None) -> tuple[str, int]:
    """A worker accepts the HIT, our page opens the assignment (for ``page_worker_id``, by
    default the same worker) and the worker submits; (AssignmentId, our assignment id)."""
    from sqlalchemy import select

    from backend.annotation.models import Task
    from backend.annotation.service import start_assignment
    from backend.crowd.models import CrowdHit
    from tests.backend.market.helpers import accept, submit

    market_id = accept(hit_id, worker_id)
    with session_scope() as session:
        task_id = session.scalar(select(CrowdHit.task_id).where(CrowdHit.hit_id == hit_id))
        task = session.get_one(Task, task_id)
        ours = start_assignment(session, task, market_id, page_worker_id or worker_id, hit_id)
        ours.status = "submitted"
        session.flush()
        our_id = ours.id
    resp = submit(base, market_id, labels="ok")
    assert resp.status_code == 200, resp.text
    return market_id, our_id


def admin_headers(client: Any) -> dict[str, str]:
    from backend.accounts.service import create_admin

    with session_scope() as session:
        create_admin(session, ADMIN_EMAIL, ADMIN_PASSWORD)
    resp = client.post("/api/auth/token", json={"email": ADMIN_EMAIL, "password": ADMIN_PASSWORD})
    assert resp.status_code == 200, resp.text
    return {"Authorization": f"Bearer {resp.json()['access_token']}"}


def synced_submission(base: str, hit_id: str, worker_id: str) -> int:
    """A worker submits on the HIT and our sync accepts it; our assignment id."""
    from backend.config import get_settings
    from backend.crowd.client import make_client
    from backend.pipeline import sync

    _, ours = worker_submits(base, hit_id, worker_id)
    with session_scope() as session:
        assert sync(session, make_client(get_settings())).accepted == 1
    return ours
