"""Training: a gold clip qualifies new workers. The clip's HIT is open to everyone; the other
HITs require the "passed training" qualification, which the QC job grants on a pass."""

from __future__ import annotations

from pathlib import Path

import httpx
from sqlalchemy import select
from typer.testing import CliRunner

from backend.db import session_scope
from tests.backend.quality.helpers import (
    ADMIN_EMAIL,
    ADMIN_PASSWORD,
    crowd_submits,
    sync_submissions,
)


def _publish_with_training(capture: Path) -> tuple[int, int, list[str]]:
    """Import; make the first hand task a training clip from the ground truth (through the
    CLI); publish every hand task requiring the qualification. (sequence, clip task, HITs)"""
    from backend.accounts.service import create_admin
    from backend.annotation.models import Task
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.cli import app
    from backend.config import get_settings
    from backend.crowd.client import make_client
    from backend.crowd.publish import publish_task, requirements
    from backend.crowd.schemas import PublishOptions
    from backend.storage import get_storage

    sequence_id = import_path(capture)[0].sequence_id
    with session_scope() as session:
        create_admin(session, ADMIN_EMAIL, ADMIN_PASSWORD)
        task_ids = [t.id for t in create_tasks(session, get_storage(), sequence_id)
                    if t.kind == "hand"]
    made = CliRunner().invoke(app, ["training", "create", str(task_ids[0]),
                                    "--from-truth", str(capture)])
    assert made.exit_code == 0, made.output
    again = CliRunner().invoke(app, ["training", "create", str(task_ids[0]),
                                     "--from-truth", str(capture)])
    assert again.exit_code == 2 and "already a training clip" in again.output
    client = make_client(get_settings())
    options = PublishOptions(min_approval_rate=None, require_training=True, max_assignments=2)
    with session_scope() as session, session.no_autoflush:
        reqs = requirements(session, client, options)
    hit_ids = []
    for task_id in task_ids:
        with session_scope() as session, session.no_autoflush:
            hit_ids.append(publish_task(session, client, session.get_one(Task, task_id),
                                        options, reqs)[0])
    return sequence_id, task_ids[0], hit_ids


def _visible_hits(base: str, index: int) -> list[str]:
    from backend.crowd.simulate import WORKER_EMAIL, WORKER_PASSWORD

    login = httpx.post(f"{base}/api/portal/login", json={
        "email": WORKER_EMAIL.format(index=index), "password": WORKER_PASSWORD.format(index=index)})
    token = login.json()["access_token"]
    hits = httpx.get(f"{base}/api/portal/hits", headers={"Authorization": f"Bearer {token}"})
    return [h["hit_id"] for h in hits.json()]


def test_passing_the_training_clip_grants_the_qualification(crowd_url: str,
                                                            training_capture: Path) -> None:
    from backend.crowd.models import CrowdWorkerAction
    from backend.jobs.runner import execute
    from backend.quality.models import QCReport
    from backend.quality.service import qc_key

    sequence_id, _clip_task, hit_ids = _publish_with_training(training_capture)
    # New workers see only the training HIT; one labels it well, one spams it.
    outcomes = crowd_submits(crowd_url, training_capture, ["careful", "spammer"])
    assert [o.hit_id for o in outcomes] == [hit_ids[0], hit_ids[0]]
    assert _visible_hits(crowd_url, 1) == []  # done with training, nothing else yet
    sync_submissions()
    execute(qc_key(sequence_id, "hand:0"))

    with session_scope() as session:
        reports = {r.worker_id: r for r in session.scalars(select(QCReport))}
        granted = set(session.scalars(select(CrowdWorkerAction.worker_id).where(
            CrowdWorkerAction.kind == "qualification")))
    careful, spammer = outcomes
    assert reports[careful.worker_id].method == "gold"
    assert reports[careful.worker_id].outcome == "approve", reports[careful.worker_id].reasons
    assert "qualification was granted" in reports[careful.worker_id].action_detail
    assert reports[spammer.worker_id].outcome == "reject"
    assert granted == {careful.worker_id}
    assert sorted(_visible_hits(crowd_url, 1)) == sorted(hit_ids[1:])
    assert not set(hit_ids[1:]) & set(_visible_hits(crowd_url, 2))  # the spammer did not pass
