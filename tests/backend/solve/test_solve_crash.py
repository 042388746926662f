"""A queue worker killed (kill -9) in the middle of a solve: once its lease runs out the next
worker solves the run again from the start, and the run ends done once, with its result
stored."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sqlalchemy import select

from backend.db import session_scope
from tests.servers import wait_for


@pytest.fixture
def database_url(tmp_path: Path) -> str:
    """SQLite only: the drill is about the worker, not the database."""
    return f"sqlite:///{tmp_path / 'test.db'}"


def _state(run_id: int) -> tuple[str, str, int]:
    """(the solve run's status, its job's status, the job's attempts)."""
    from backend.jobs.models import Job
    from backend.solve.models import SolveRun
    from backend.solve.service import job_key

    with session_scope() as session:
        run = session.get_one(SolveRun, run_id)
        job = session.scalars(select(Job).where(Job.key == job_key(run_id))).one()
        return run.status, job.status, job.attempts


def _worker(env: dict[str, str], log: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-m", "backend.cli", "worker", "--workers", "1"],
                            env=env, stdout=log.open("ab"), stderr=subprocess.STDOUT)


@pytest.mark.slow
def test_a_worker_killed_mid_solve_leaves_the_run_to_the_next_worker(
        app_env: dict, small_capture: Path, tmp_path: Path) -> None:
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.solve.models import SolveRun
    from backend.solve.service import request_solve
    from backend.storage import get_storage
    from tests.backend.solve.test_solve_api import _approve_from_truth

    sequence_id = import_path(small_capture)[0].sequence_id
    with session_scope() as session:
        create_tasks(session, get_storage(), sequence_id)
    _approve_from_truth(small_capture, sequence_id)
    with session_scope() as session:
        run_id = request_solve(session, sequence_id, optimiser="default").id

    # A short lease, so the dead worker's job is taken over in seconds; the queue message went
    # to this process's queue, and a starting worker sends queued jobs to itself.
    env = {**os.environ, **app_env, "DEXLABEL_JOB_LEASE_S": "2"}
    log = tmp_path / "workers.log"
    first = _worker(env, log)
    try:
        wait_for(lambda: _state(run_id)[0] == "running", "the first worker to start solving",
                 timeout_s=120, interval_s=0.1)
        time.sleep(0.5)  # inside the solver
    finally:
        first.send_signal(signal.SIGKILL)  # no clean-up runs
        first.wait(timeout=10)
    assert _state(run_id) == ("running", "running", 1), "the solve ended before the kill"
    time.sleep(2.5)  # its lease runs out: nobody renews it any more

    second = _worker(env, log)
    try:
        wait_for(lambda: _state(run_id)[1] in ("done", "failed"),
                 "the second worker to finish the solve", timeout_s=600, interval_s=0.1)
    finally:
        second.terminate()
        second.wait(timeout=30)
    assert _state(run_id) == ("done", "done", 2), log.read_text()[-3000:]
    with session_scope() as session:
        runs = list(session.scalars(select(SolveRun).where(SolveRun.sequence_id == sequence_id)))
    assert [(r.id, r.status) for r in runs] == [(run_id, "done")]
    assert runs[0].result_key and get_storage().exists(runs[0].result_key)
