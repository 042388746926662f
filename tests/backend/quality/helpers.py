"""A small crowd on a synthetic capture: publish its hand tasks, let simulated workers submit."""

from __future__ import annotations

from pathlib import Path

import httpx
import numpy as np

from backend.config import get_settings
from backend.db import session_scope

ADMIN_EMAIL = "qc-admin@example.org"
ADMIN_PASSWORD = "correct horse battery"


def publish_hand_tasks(capture: Path, max_assignments: int) -> tuple[int, list[str]]:
    """Import, create tasks, publish each hand task; (sequence id, HIT ids in task order)."""
    from backend.accounts.service import create_admin
    from backend.annotation.models import Task
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.crowd.client import make_client
    from backend.crowd.publish import publish_task
    from backend.crowd.schemas import PublishOptions
    from backend.storage import get_storage

    sequence_id = import_path(capture)[0].sequence_id
    with session_scope() as session:
        create_admin(session, ADMIN_EMAIL, ADMIN_PASSWORD)
        task_ids = [t.id for t in create_tasks(session, get_storage(), sequence_id)
                    if t.kind == "hand"]
    client, hit_ids = make_client(get_settings()), []
    options = PublishOptions(min_approval_rate=None, max_assignments=max_assignments)
    for task_id in task_ids:
        with session_scope() as session, session.no_autoflush:
            task = session.get_one(Task, task_id)
            hit_ids.append(publish_task(session, client, task, options, [])[0])
    return sequence_id, hit_ids


def crowd_submits(base: str, capture: Path, profiles: list[str], seed: int = 0,
                  first_worker: int = 1) -> list:
    """Simulated workers first_worker.. with these profiles, in order, each taking the first
    HIT on offer."""
    from backend.captures.truth import CaptureTruth
    from backend.crowd.simulate import WorkerClient, _work_one, admin_token

    rng = np.random.default_rng(seed)
    truth = CaptureTruth(capture)
    with httpx.Client(timeout=30.0) as http:
        admin = admin_token(http, base, ADMIN_EMAIL, ADMIN_PASSWORD)
        client = WorkerClient(http, base)
        return [_work_one(client, admin, first_worker + i, profile, truth, rng)
                for i, profile in enumerate(profiles)]


def sync_submissions() -> None:
    from backend.crowd.client import make_client
    from backend.pipeline import sync

    with session_scope() as session:
        sync(session, make_client(get_settings()))


def submit_direct(task_id: int, worker: str, tracks: list) -> int:
    """An assignment submitted through a direct link (no marketplace), as the page writes it."""
    from backend.annotation.models import Assignment, Track
    from backend.db import utcnow

    with session_scope() as session:
        assignment = Assignment(task_id=task_id, worker_id=worker, external_id=f"direct-{worker}",
                                status="submitted", version=1, working_time_s=150.0,
                                submitted_at=utcnow())
        assignment.tracks = [Track(point_index=p, keyframes=rows) for p, rows in enumerate(tracks)]
        session.add(assignment)
        session.flush()
        return assignment.id


def store_solve(sequence_id: int, object_poses: np.ndarray) -> int:
    """A finished solve run of the sequence whose stored result holds these object poses
    (O, F, 3, 4) object-to-world, and nothing about the hand; its id."""
    from backend.solve.service import store_object_poses

    with session_scope() as session:
        return store_object_poses(session, sequence_id, object_poses).id
