"""Leases that fit a crash: a minute's lease kept alive by the heartbeat, a reaper pass every
half minute, so a dead worker's job is taken over within two minutes; the host that ran each
attempt is recorded; a job retried after its worker died reports every attempt's actions."""

from __future__ import annotations

import os
import socket
import threading
import time
from datetime import UTC, datetime, timedelta

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select, update

from backend.config import Settings, get_settings
from backend.db import session_scope
from backend.jobs.attempts import record_actions
from backend.jobs.consumer import REAP_EVERY_S, reap_jobs, requeue_stale
from backend.jobs.models import Job
from backend.jobs.runner import HEARTBEAT_FRACTION, _claim, checkpoint, execute, job_handler
from backend.jobs.service import enqueue_job
from backend.queue import huey


@job_handler("test-lease-echo")
def _echo(args: dict) -> dict:
    return {"echo": args["value"]}


def _job(key: str) -> Job:
    with session_scope() as session:
        job = session.scalars(select(Job).where(Job.key == key)).one()
        session.expunge(job)
        return job


def _as_host(monkeypatch: pytest.MonkeyPatch, name: str) -> str:
    monkeypatch.setenv("DEXLABEL_HOST_NAME", name)
    get_settings.cache_clear()
    return f"{name}:{os.getpid()}"


def test_the_default_lease_lets_another_worker_take_a_dead_workers_job_within_two_minutes(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DEXLABEL_JOB_LEASE_S", raising=False)
    lease = Settings().job_lease_s
    assert 30 <= lease <= 60
    # The heartbeat renews well within the lease (a renewal may fail and the next still
    # comes in time); the job is queued again within lease + a reaper interval of the kill.
    assert lease * HEARTBEAT_FRACTION <= lease / 3
    assert lease + REAP_EVERY_S < 120


def test_each_minutes_reaper_pass_schedules_one_half_a_minute_later(app_env: dict) -> None:
    huey.flush()
    reap_jobs.call_local()
    later = [t for t in huey.pending() + huey.scheduled()
             if t.name.endswith("reap_jobs_again")]
    assert len(later) == 1
    assert later[0].eta is not None
    due = (later[0].eta - datetime.now(UTC).replace(tzinfo=None)).total_seconds()
    assert REAP_EVERY_S - 5 < due <= REAP_EVERY_S
    huey.flush()


def test_a_job_whose_worker_stops_heartbeating_is_taken_over_once_its_lease_runs_out(
        app_env: dict, client: TestClient, admin_headers: dict,
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DEXLABEL_JOB_LEASE_S", "1")
    first_host = _as_host(monkeypatch, "worker-a")
    with session_scope() as session:
        enqueue_job(session, "test-lease-echo", "lease:1", {"value": 3})
    huey.flush()
    # The first worker claims the job and dies at once: no heartbeat ever renews its lease.
    # The lease starts while the claim runs (a loaded machine can take most of a second over
    # it): it cannot run out before 1 s from the claim's start, and must by 1 s from its end.
    asked = time.monotonic()
    assert _claim("lease:1") is not None
    claimed = time.monotonic()
    assert _job("lease:1").host == first_host
    requeued: list[str] = []
    while not requeued:
        assert time.monotonic() - claimed < 5, "the dead worker's job was not taken over"
        requeued = requeue_stale()
        time.sleep(0.05)
    since_asked, since_claimed = time.monotonic() - asked, time.monotonic() - claimed
    assert requeued == ["lease:1"] and since_asked >= 0.9 and since_claimed < 2.0, (
        since_asked, since_claimed)

    second_host = _as_host(monkeypatch, "worker-b")
    execute("lease:1")
    job = _job("lease:1")
    assert (job.status, job.attempts, job.result, job.host) == (
        "done", 2, {"echo": 3}, second_host)
    assert [(e["attempt"], e["host"]) for e in job.attempt_log or []] == [
        (1, first_host), (2, second_host)]
    read = client.get(f"/api/jobs/{job.id}", headers=admin_headers).json()
    assert read["host"] == second_host
    assert [e["host"] for e in read["attempt_log"]] == [first_host, second_host]


def test_the_host_defaults_to_the_machines_name(app_env: dict,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DEXLABEL_HOST_NAME", raising=False)
    get_settings.cache_clear()
    with session_scope() as session:
        enqueue_job(session, "test-lease-echo", "lease:host", {"value": 1})
    execute("lease:host")
    assert _job("lease:host").host == f"{socket.gethostname()}:{os.getpid()}"


PAID: list[tuple[int, int]] = []  # (item, attempt) of each payment made
FIRST_PAID, RELEASE = threading.Event(), threading.Event()


@job_handler("test-pay")
def _pay(args: dict) -> dict:
    """Pays each item once (a payment already made is not made again); the first attempt
    stops after its first payment until the test releases it."""
    attempt = 1 if not FIRST_PAID.is_set() else 2
    made: dict[str, int] = {}
    for item in range(int(args["items"])):
        if any(paid == item for paid, _ in PAID):
            continue
        checkpoint()
        with session_scope() as session:
            PAID.append((item, attempt))
            record_actions(session, {"paid": 1})
        made["paid"] = made.get("paid", 0) + 1
        if attempt == 1:
            FIRST_PAID.set()
            assert RELEASE.wait(30)
    return {"actions": made}


def test_a_job_retried_after_its_worker_died_reports_every_attempts_actions(
        app_env: dict) -> None:
    PAID.clear()
    FIRST_PAID.clear()
    RELEASE.clear()
    with session_scope() as session:
        enqueue_job(session, "test-pay", "pay:1", {"items": 3})
    first = threading.Thread(target=execute, args=("pay:1",))
    first.start()
    try:
        assert FIRST_PAID.wait(30)
        # The first worker stops answering after one payment: its lease runs out and the
        # next attempt makes the other two.
        with session_scope() as session:
            session.execute(update(Job).where(Job.key == "pay:1").values(
                lease_until=datetime.now(UTC) - timedelta(seconds=1)))
        execute("pay:1")
    finally:
        RELEASE.set()
        first.join(30)
    assert sorted(PAID) == [(0, 1), (1, 2), (2, 2)]
    job = _job("pay:1")
    assert (job.status, job.attempts) == ("done", 2)
    assert job.result is not None
    assert job.result["actions"] == {"paid": 3}, job.result
    assert [(a["attempt"], a["actions"]) for a in job.result["attempts"]] == [
        (1, {"paid": 1}), (2, {"paid": 2})]
