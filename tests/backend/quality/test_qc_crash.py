"""A queue worker killed in the middle of a QC job: the job is retried by the next worker and
completes once, with one decision and one payment per assignment."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import pytest
from sqlalchemy import select

from backend.db import session_scope
from tests.backend.quality.helpers import crowd_submits, publish_hand_tasks, sync_submissions
from tests.servers import wait_for


def _worker(env: dict[str, str], log: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "backend.cli", "worker", "--workers", "1"],
                            env=env, stdout=log.open("ab"), stderr=subprocess.STDOUT)


def _payments() -> list:
    from backend.crowd.models import CrowdPayment

    with session_scope() as session:
        return list(session.scalars(select(CrowdPayment.id)))


def _job(key: str):
    from backend.jobs.models import Job

    with session_scope() as session:
        job = session.scalar(select(Job).where(Job.key == key))
        session.expunge(job)
        return job


@pytest.mark.slow
def test_killed_worker_mid_qc_job_is_retried_and_acts_once(crowd_url: str, qc_capture: Path,
                                                            tmp_path: Path) -> None:
    from backend.crowd.models import CrowdPayment
    from backend.quality.models import QCReport
    from backend.quality.service import qc_key

    sequence_id, _ = publish_hand_tasks(qc_capture, max_assignments=1)
    crowd_submits(crowd_url, qc_capture, ["careful"] * 5 + ["spammer"])
    sync_submissions()
    key = qc_key(sequence_id, "hand:0")
    assert _job(key).status == "queued"

    base_env = {**os.environ, "DEXLABEL_PUBLIC_URL": crowd_url,
                # a queued job is re-sent by a starting worker at once (its message went to
                # this test process's own queue file)
                "DEXLABEL_JOB_REQUEUE_AFTER_S": "0.001"}
    log = tmp_path / "workers.log"
    first = _worker({**base_env, "DEXLABEL_JOB_PAUSE_S": "60", "DEXLABEL_JOB_LEASE_S": "3"}, log)
    try:  # killed after its first action (a payment), before the other five
        wait_for(lambda: len(_payments()) == 1, "the first worker's first action", 60, 0.2)
    finally:
        first.send_signal(signal.SIGKILL)  # killed mid-job: no clean-up runs
        first.wait(timeout=10)
    dead = _job(key)
    assert (dead.status, dead.attempts) == ("running", 1)
    wait_for(lambda: dead.lease_until.replace(tzinfo=UTC) < datetime.now(UTC),
             "the dead worker's lease to run out", timeout_s=10)

    second = _worker(base_env, log)
    try:
        done = wait_for(lambda: (j := _job(key)).status in ("done", "failed") and j,
                        "the second worker to finish the job", timeout_s=90, interval_s=0.2)
    finally:
        second.terminate()
        second.wait(timeout=15)
    assert (done.status, done.attempts) == ("done", 2), log.read_text()[-3000:]
    # The result counts the first attempt's payment too, and says who did what.
    assert done.result["actions"] == {"approved": 5, "rejected": 1}, done.result
    assert [sum(a["actions"].values()) for a in done.result["attempts"]] == [1, 5]
    assert all(a["host"] for a in done.result["attempts"])
    with session_scope() as session:
        reports = list(session.scalars(select(QCReport)))
        payments = list(session.scalars(select(CrowdPayment)))
    assert len(reports) == 6
    assert sorted(r.action for r in reports) == ["approved"] * 5 + ["rejected"]
    decided = [(p.kind, p.assignment_id) for p in payments if p.kind != "bonus"]
    assert len(decided) == len({p[1] for p in decided}) == 6
