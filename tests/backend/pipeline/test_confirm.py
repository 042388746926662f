"""The page's own submit notification: the confirm job checks the submission with the requester
API (retrying until the marketplace has it) and queues the target's quality check."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sqlalchemy import select

from backend.db import session_scope
from tests.backend.quality.helpers import crowd_submits, publish_hand_tasks


def _job(key: str):
    from backend.jobs.models import Job

    with session_scope() as session:
        job = session.scalar(select(Job).where(Job.key == key))
        if job is not None:
            session.expunge(job)
        return job


def test_submit_in_the_page_is_confirmed_without_a_sync(crowd_url: str,
                                                        training_capture: Path) -> None:
    from backend.annotation.models import Assignment
    from backend.crowd.models import CrowdSubmission
    from backend.jobs.runner import execute
    from backend.quality.service import qc_key

    sequence_id, _ = publish_hand_tasks(training_capture, max_assignments=1)
    [outcome] = crowd_submits(crowd_url, training_capture, ["careful"])
    with session_scope() as session:
        ours = session.scalar(select(Assignment).where(
            Assignment.external_id == outcome.assignment_id))
        key = f"confirm:{ours.id}"
    assert _job(key).status == "queued"
    assert _job(qc_key(sequence_id, "hand:0")) is None  # not before the marketplace agrees
    execute(key)
    assert (_job(key).status, _job(key).result["state"]) == ("done", "accepted")
    assert _job(key).result["message"] == f"assignment {ours.id}: accepted"
    with session_scope() as session:
        [row] = session.scalars(select(CrowdSubmission))
        assert (row.hit_id, row.worker_id) == (outcome.hit_id, outcome.worker_id)
    assert _job(qc_key(sequence_id, "hand:0")).status == "queued"


def test_confirm_retries_until_the_marketplace_has_the_submission(crowd_url: str,
                                                                  training_capture: Path) -> None:
    from backend.annotation.models import Task
    from backend.annotation.schemas import TracksSave
    from backend.annotation.service import start_assignment
    from backend.crowd.models import CrowdHit
    from backend.jobs.runner import execute
    from backend.pipeline import submit
    from tests.backend.market.helpers import accept
    from tests.backend.market.helpers import submit as market_submit
    from worker.synth.annotators import annotate

    _, hit_ids = publish_hand_tasks(training_capture, max_assignments=1)
    market_id = accept(hit_ids[0], "AWORKERCONFIRM01")
    with session_scope() as session:  # our page opens the assignment and the worker submits
        task_id = session.scalar(select(CrowdHit.task_id).where(CrowdHit.hit_id == hit_ids[0]))
        task = session.get_one(Task, task_id)
        ours = start_assignment(session, task, market_id, "AWORKERCONFIRM01", hit_ids[0])
        frames = task.sequence.num_frames
        xy = np.full((frames, 21, 2), 100.0)
        work = annotate(xy, np.ones((frames, 21), bool), (320, 240), "careful",
                        np.random.default_rng(0))
        body = TracksSave(version=ours.version, tracks=[
            {"point": p, "keyframes": rows} for p, rows in enumerate(work.tracks)])
        submit(session, ours, body)
        key = f"confirm:{ours.id}"
    execute(key)  # the page's form post to the marketplace has not arrived yet
    job = _job(key)
    assert (job.status, job.attempts) == ("retrying", 1)
    assert "not submitted on the marketplace yet" in job.error
    assert market_submit(crowd_url, market_id, labels="ok").status_code == 200
    execute(key)
    assert (_job(key).status, _job(key).attempts) == ("done", 2)
