"""A QC job that works far longer than its lease, with a second worker whose reaper looks for
expired leases every second: the heartbeat keeps the lease, so one attempt acts on every
report once, and no automatic decision is relabelled as an admin's."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from sqlalchemy import select

from backend.db import session_scope
from tests.backend.quality.helpers import crowd_submits, publish_hand_tasks, sync_submissions
from tests.backend.quality.test_qc_crash import _job
from tests.servers import wait_for

# A consumer whose reaper runs every second instead of every minute.
WORKER = ("import huey.consumer; huey.consumer.Scheduler.periodic_task_seconds = 1; "
          "from backend.cli import app; app(['worker', '--workers', '2'])")


@pytest.mark.slow
def test_a_qc_job_longer_than_its_lease_runs_once_with_two_workers(
        crowd_url: str, qc_capture: Path, tmp_path: Path) -> None:
    from backend.crowd.models import CrowdPayment
    from backend.quality.models import QCReport
    from backend.quality.service import qc_key

    sequence_id, _ = publish_hand_tasks(qc_capture, max_assignments=1)
    crowd_submits(crowd_url, qc_capture, ["careful"] * 5 + ["spammer"])
    sync_submissions()
    key = qc_key(sequence_id, "hand:0")

    # Each of the six actions is followed by a 1.5 s pause: the job runs about 9 s on a 1 s
    # lease. A starting worker sends queued jobs to itself (the message went to this test
    # process's queue file).
    env = {**os.environ, "DEXLABEL_PUBLIC_URL": crowd_url, "DEXLABEL_JOB_LEASE_S": "1",
           "DEXLABEL_JOB_PAUSE_S": "1.5"}
    log = tmp_path / "workers.log"
    workers = [subprocess.Popen([sys.executable, "-c", WORKER], env=env,
                                stdout=log.open("ab"), stderr=subprocess.STDOUT)
               for _ in range(2)]
    try:
        done = wait_for(lambda: (j := _job(key)).status in ("done", "failed") and j,
                        "the QC job to finish", timeout_s=180)
    finally:
        for worker in workers:
            worker.terminate()
        for worker in workers:
            worker.wait(timeout=30)
    assert (done.status, done.attempts) == ("done", 1), log.read_text()[-3000:]
    with session_scope() as session:
        reports = list(session.scalars(select(QCReport)))
        payments = list(session.scalars(select(CrowdPayment)))
    assert sorted(r.action for r in reports) == ["approved"] * 5 + ["rejected"]
    assert not [r for r in reports if r.action_detail == "decided by an admin"]
    decided = [p.assignment_id for p in payments if p.kind != "bonus"]
    assert len(decided) == len(set(decided)) == 6
