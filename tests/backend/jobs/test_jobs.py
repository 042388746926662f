"""The job table and runner: claim once, retry with backoff, fail for good, reap dead workers."""

from __future__ import annotations

import threading
import time
from datetime import UTC, datetime, timedelta

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select, update

from backend.db import session_scope
from backend.jobs.consumer import requeue_stale
from backend.jobs.models import Job
from backend.jobs.runner import checkpoint, execute, job_handler, retry_delay
from backend.jobs.service import enqueue_job
from backend.queue import huey

CALLS: list[dict] = []


@job_handler("test-echo")
def _echo(args: dict) -> dict:
    CALLS.append(args)
    return {"echo": args["value"]}


@job_handler("test-broken")
def _broken(args: dict) -> dict:
    CALLS.append(args)
    raise ValueError(f"boom {args['value']}")


@pytest.fixture(autouse=True)
def _clear_calls() -> None:
    CALLS.clear()
    huey.flush()


def _queue(kind: str, key: str, value: int = 1) -> None:
    with session_scope() as session:
        enqueue_job(session, kind, key, {"value": value})


def _job(key: str) -> Job:
    with session_scope() as session:
        job = session.scalar(select(Job).where(Job.key == key))
        session.expunge(job)
        return job


def test_job_runs_once_and_records_its_result(app_env: dict) -> None:
    _queue("test-echo", "echo:1", 7)
    assert huey.pending_count() == 1  # the queue message went out after the commit
    execute("echo:1")
    execute("echo:1")  # a duplicate message finds the job done and does nothing
    job = _job("echo:1")
    assert (job.status, job.attempts, job.result, job.error) == ("done", 1, {"echo": 7}, None)
    assert CALLS == [{"value": 7}]


def _enqueue_in_a_failing_unit() -> None:
    with session_scope() as session:
        enqueue_job(session, "test-echo", "echo:lost", {"value": 1})
        raise RuntimeError("the unit of work failed")


def test_enqueue_of_a_rolled_back_unit_sends_nothing(app_env: dict) -> None:
    with pytest.raises(RuntimeError, match="the unit of work failed"):
        _enqueue_in_a_failing_unit()
    assert huey.pending_count() == 0
    with session_scope() as session:
        assert session.scalar(select(Job).where(Job.key == "echo:lost")) is None


def test_failing_job_is_retried_with_backoff_then_failed(app_env: dict,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from backend.config import get_settings

    monkeypatch.setenv("DEXLABEL_JOB_MAX_ATTEMPTS", "2")
    get_settings.cache_clear()
    _queue("test-broken", "broken:1", 3)
    huey.flush()
    execute("broken:1")
    job = _job("broken:1")
    assert (job.status, job.attempts) == ("retrying", 1)
    assert "ValueError: boom 3" in job.error
    [retry] = huey.pending()  # the retry is sent with its backoff delay as the ETA
    assert retry.args == ("broken:1",) and retry.eta is not None
    execute("broken:1")
    job = _job("broken:1")
    assert (job.status, job.attempts) == ("failed", 2)
    assert job.finished_at is not None
    assert len(CALLS) == 2


def testretry_delay_doubles_from_the_base(app_env: dict) -> None:
    assert [retry_delay(a) for a in (1, 2, 3, 4)] == [5.0, 10.0, 20.0, 40.0]


def test_reaper_requeues_the_job_of_a_dead_worker(app_env: dict) -> None:
    _queue("test-echo", "echo:dead", 5)
    huey.flush()
    past = datetime.now(UTC) - timedelta(minutes=5)
    with session_scope() as session:  # a worker claimed it, then was killed
        session.execute(update(Job).where(Job.key == "echo:dead").values(
            status="running", attempts=1, lease_until=past))
    assert requeue_stale() == ["echo:dead"]
    assert huey.pending_count() == 1
    execute("echo:dead")
    job = _job("echo:dead")
    assert (job.status, job.attempts) == ("done", 2)
    assert requeue_stale() == []


def test_a_starting_worker_takes_jobs_queued_where_it_cannot_see_their_message(
        app_env: dict) -> None:
    """A job queued by a process whose queue no consumer reads (another queue setting, a
    message lost while no worker ran) is sent again when a worker starts, and runs once."""
    _queue("test-echo", "echo:elsewhere", 5)
    huey.flush()  # the message is gone; the row still says queued
    assert requeue_stale() == []  # recent: the reaper leaves it alone
    assert requeue_stale(starting=True) == ["echo:elsewhere"]
    assert huey.pending_count() == 1
    execute("echo:elsewhere")
    execute("echo:elsewhere")  # a duplicate message finds the job done: it does not run again
    job = _job("echo:elsewhere")
    assert (job.status, job.attempts) == ("done", 1) and len(CALLS) == 1


def test_reaper_leaves_a_running_job_with_a_live_lease(app_env: dict) -> None:
    _queue("test-echo", "echo:live", 5)
    future = datetime.now(UTC) + timedelta(minutes=5)
    with session_scope() as session:
        session.execute(update(Job).where(Job.key == "echo:live").values(
            status="running", attempts=1, lease_until=future))
    assert requeue_stale() == []
    execute("echo:live")  # another worker holds it: not claimed
    assert _job("echo:live").attempts == 1 and CALLS == []


def test_admin_lists_jobs_and_reruns_a_failed_one(client: TestClient,
                                                  admin_headers: dict[str, str]) -> None:
    _queue("test-broken", "broken:api", 1)
    with session_scope() as session:
        session.execute(update(Job).where(Job.key == "broken:api").values(
            status="failed", attempts=5, error="ValueError: boom"))
    listed = client.get("/api/jobs?status=failed", headers=admin_headers)
    assert listed.status_code == 200
    [row] = listed.json()
    assert (row["key"], row["error"]) == ("broken:api", "ValueError: boom")
    again = client.post(f"/api/jobs/{row['id']}/retry", headers=admin_headers)
    assert again.status_code == 200 and again.json()["status"] == "queued"
    assert again.json()["attempts"] == 0
    twice = client.post(f"/api/jobs/{row['id']}/retry", headers=admin_headers)
    assert twice.status_code == 409 and "already queued" in twice.json()["detail"]
    assert client.get("/api/jobs/99999", headers=admin_headers).status_code == 404
    assert client.get("/api/jobs").status_code == 401


def test_first_submissions_of_two_views_at_once_queue_one_qc_job(
        client: TestClient, admin_headers: dict[str, str], small_capture,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Two views of one target submitted at the same moment, before its QC job exists: both
    submits succeed and the target has one QC job row that counts both asks."""
    from backend.captures.flows import import_path
    from backend.config import get_settings
    from backend.quality import service as quality_service
    from backend.quality.service import qc_key

    sequence_id = import_path(small_capture)[0].sequence_id
    made = client.post(f"/api/sequences/{sequence_id}/tasks", headers=admin_headers)
    hands = [t for t in made.json() if t["kind"] == "hand"][:2]
    tokens = []
    for n, task in enumerate(hands):
        link = client.post(f"/api/tasks/{task['id']}/assignments",
                           json={"worker_id": f"W{n}"}, headers=admin_headers)
        tokens.append(link.json()["token"])
    tracks = [{"point": p, "keyframes": [[0, 10.0 + p, 20.0, 1], [5, 30.0 + p, 40.0, 1]]}
              for p in range(21)]

    # On PostgreSQL both units of work reach the QC job's enqueue before either commits. (On
    # SQLite the second waits for the first one's write lock before it gets there.)
    together = get_settings().database_url.startswith("postgresql")
    barrier = threading.Barrier(2, timeout=30)
    real_enqueue = quality_service.enqueue_job

    def enqueue_together(*args, **kwargs):  # type: ignore[no-untyped-def]
        if together:
            barrier.wait()
        return real_enqueue(*args, **kwargs)

    monkeypatch.setattr(quality_service, "enqueue_job", enqueue_together)
    answers: list = [None, None]

    def submit(n: int) -> None:
        try:
            answers[n] = client.post("/api/annotate/submit",
                                     json={"version": 0, "tracks": tracks},
                                     headers={"Authorization": f"Bearer {tokens[n]}"})
        except Exception as exc:  # the test client raises what the app did not handle
            answers[n] = exc

    threads = [threading.Thread(target=submit, args=(n,)) for n in (0, 1)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    assert all(not isinstance(a, Exception) for a in answers), answers
    assert [a.status_code for a in answers] == [200, 200], [a.text for a in answers]
    assert [a.json()["status"] for a in answers] == ["submitted", "submitted"]
    with session_scope() as session:
        jobs = list(session.scalars(select(Job).where(Job.kind == "qc")))
    assert [(j.key, j.status, j.requests) for j in jobs] == [
        (qc_key(sequence_id, "hand:0"), "queued", 2)]


SLOW_RUNS: list[int] = []


@job_handler("test-slow")
def _slow(args: dict) -> dict:
    """Works for args["seconds"] in steps, with a checkpoint between steps."""
    SLOW_RUNS.append(1)
    steps = int(args["seconds"] / 0.25)
    for _ in range(steps):
        time.sleep(0.25)
        checkpoint()
    return {"steps": steps}


def test_a_job_that_works_longer_than_its_lease_keeps_it(
        app_env: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    """A 1 s lease and 4 s of work: the heartbeat renews the lease, so the reaper and other
    workers asking for the job all along leave it to its one attempt."""
    from backend.config import get_settings

    monkeypatch.setenv("DEXLABEL_JOB_LEASE_S", "1")
    get_settings.cache_clear()
    SLOW_RUNS.clear()
    with session_scope() as session:
        enqueue_job(session, "test-slow", "slow:1", {"seconds": 4})
    runner = threading.Thread(target=execute, args=("slow:1",))
    runner.start()
    requeued: list[str] = []
    while runner.is_alive():  # another worker and the reaper, as often as they can
        requeued += requeue_stale()
        execute("slow:1")
        time.sleep(0.2)
    runner.join()
    job = _job("slow:1")
    assert (job.status, job.attempts, job.result) == ("done", 1, {"steps": 16})
    assert SLOW_RUNS == [1] and requeued == []


ACTED: list[int] = []
STARTED, RELEASE = threading.Event(), threading.Event()


@job_handler("test-act")
def _act_once(args: dict) -> dict:
    """Acts after a checkpoint; the first run waits for the test before it gets there."""
    run = 2 if STARTED.is_set() else 1
    if run == 1:
        STARTED.set()
        assert RELEASE.wait(30)
    checkpoint()
    ACTED.append(run)
    return {"acted_in_run": run}


def test_an_attempt_that_lost_its_job_stops_at_its_next_checkpoint_without_acting(
        app_env: dict) -> None:
    ACTED.clear()
    STARTED.clear()
    RELEASE.clear()
    with session_scope() as session:
        enqueue_job(session, "test-act", "act:1", {})
    first = threading.Thread(target=execute, args=("act:1",))
    first.start()
    try:
        assert STARTED.wait(30)
        # The first attempt's lease runs out (its heartbeat could not reach the database) and
        # another worker claims the job and acts.
        with session_scope() as session:
            session.execute(update(Job).where(Job.key == "act:1").values(
                lease_until=datetime.now(UTC) - timedelta(seconds=1)))
        execute("act:1")
        assert ACTED == [2]
    finally:
        RELEASE.set()
        first.join(30)
    assert ACTED == [2], "the attempt that lost its job acted anyway"
    job = _job("act:1")
    assert (job.status, job.attempts, job.result, job.error) == (
        "done", 2, {"acted_in_run": 2}, None)


class _QueueDown:
    """The queue task while the queue is down: sending raises, as Redis's client does."""

    def __call__(self, *args: object) -> None:
        raise ConnectionError("Error 111 connecting to 127.0.0.1:6379. Connection refused.")

    def schedule(self, *args: object, **kwargs: object) -> None:
        self()


def test_a_job_the_queue_did_not_take_is_sent_by_the_next_reaper_pass(
        app_env: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    """The queue was down when the unit of work committed: the job's row says so, and the
    reaper's next pass (every minute) sends it, not only job_requeue_after_s later."""
    from backend.jobs import runner

    monkeypatch.setattr(runner, "run_job", _QueueDown())
    _queue("test-echo", "echo:unsent", 4)  # committed all the same
    job = _job("echo:unsent")
    assert job.status == "queued" and job.lease_until is not None
    assert huey.pending_count() == 0
    monkeypatch.undo()  # the queue is back
    assert requeue_stale() == ["echo:unsent"]
    assert huey.pending_count() == 1
    assert requeue_stale() == []  # sent: nothing more to send
    execute("echo:unsent")
    assert (_job("echo:unsent").status, CALLS) == ("done", [{"value": 4}])


def test_a_retry_the_queue_did_not_take_is_sent_when_it_is_due(
        app_env: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    from backend.jobs import runner

    _queue("test-broken", "broken:unsent", 1)
    huey.flush()
    monkeypatch.setattr(runner, "run_job", _QueueDown())
    execute("broken:unsent")  # fails; its retry (due in 5 s) cannot be scheduled
    monkeypatch.undo()
    job = _job("broken:unsent")
    assert (job.status, job.attempts) == ("retrying", 1)
    assert requeue_stale() == []  # not due yet
    later = datetime.now(UTC) + timedelta(seconds=6)
    assert requeue_stale(now=later) == ["broken:unsent"]
    assert huey.pending_count() == 1


def test_after_the_queue_lost_its_messages_the_reaper_sends_every_waiting_job(
        app_env: dict) -> None:
    """A Redis restarted without persistence forgets the messages it held: the reaper's next
    pass sends every queued job at once and every retrying one at its retry time."""
    _queue("test-echo", "echo:forgotten", 1)
    _queue("test-broken", "broken:forgotten", 2)
    execute("broken:forgotten")  # now retrying, its retry scheduled in 5 s
    huey.flush()  # the queue's store is emptied
    assert requeue_stale() == []
    assert sorted(requeue_stale(queue_reset=True)) == ["broken:forgotten", "echo:forgotten"]
    sent = {task.args[0]: task.eta for task in huey.pending()}
    assert sent.keys() == {"echo:forgotten", "broken:forgotten"}
    assert sent["echo:forgotten"] is None and sent["broken:forgotten"] is not None
