"""Outages of the servers the product depends on, with throwaway servers (tests/servers.py)
stopped and started again mid-test: PostgreSQL down answers 503 with Retry-After and
/healthz names it; Redis down at enqueue time loses no job, which runs within a reaper pass
of Redis coming back; a Redis restarted empty is noticed by the reaper."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import create_engine, text

from tests.conftest import _unavailable, reset_caches
from tests.servers import ThrowawayPostgres, ThrowawayRedis, Unavailable

CLI = [sys.executable, "-m", "backend.cli"]


@pytest.fixture
def throwaway_postgres() -> Iterator[ThrowawayPostgres]:
    try:
        server = ThrowawayPostgres().start()
    except Unavailable as exc:
        _unavailable("a throwaway PostgreSQL", exc)
    yield server
    server.remove()


@pytest.fixture
def throwaway_redis() -> Iterator[ThrowawayRedis]:
    try:
        server = ThrowawayRedis().start()
    except Unavailable as exc:
        _unavailable("a throwaway Redis", exc)
    yield server
    server.remove()


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def test_database_down_answers_503_with_retry_after_and_healthz_names_it(
        throwaway_postgres: ThrowawayPostgres, monkeypatch: pytest.MonkeyPatch,
        tmp_path: Path, small_capture: Path) -> None:
    from backend.accounts.service import create_admin
    from backend.app import create_app
    from backend.captures.flows import import_path
    from backend.db import session_scope
    from backend.migrate import upgrade

    url = throwaway_postgres.url
    for key, value in {"DEXLABEL_VAR_DIR": str(tmp_path / "var"), "DEXLABEL_DATABASE_URL": url,
                       "DEXLABEL_STORAGE_URL": str(tmp_path / "storage"),
                       "DEXLABEL_ENV": "test"}.items():
        monkeypatch.setenv(key, value)
    reset_caches()
    upgrade(url)
    with session_scope() as session:
        create_admin(session, "ops@example.org", "correct horse battery")
    sequence_id = import_path(small_capture)[0].sequence_id
    try:
        with TestClient(create_app(), raise_server_exceptions=False) as client:
            admin = client.post("/api/auth/token", json={"email": "ops@example.org",
                                                         "password": "correct horse battery"})
            headers = _bearer(admin.json()["access_token"])
            tasks = client.post(f"/api/sequences/{sequence_id}/tasks", headers=headers).json()
            link = client.post(f"/api/tasks/{tasks[0]['id']}/assignments",
                               json={"worker_id": "W1"}, headers=headers).json()
            worker = _bearer(link["token"])
            tracks = [{"point": 0, "keyframes": [[0, 10.0, 20.0, 1]]}]
            saved = client.put("/api/annotate/tracks", json={"version": 0, "tracks": tracks},
                               headers=worker)
            assert saved.status_code == 200, saved.text
            healthy = client.get("/healthz")
            assert (healthy.status_code, healthy.json()) == (
                200, {"status": "ok", "database": "ok", "queue": "ok"})

            throwaway_postgres.stop()
            for answer in (client.put("/api/annotate/tracks", headers=worker,
                                      json={"version": 1, "tracks": tracks}),
                           client.get("/api/annotate/task", headers=worker)):
                assert answer.status_code == 503, answer.text
                assert answer.json()["error"] == "unavailable"
                assert "database" in answer.json()["detail"]
                assert int(answer.headers["Retry-After"]) > 0
            sick = client.get("/healthz")
            assert sick.status_code == 503 and int(sick.headers["Retry-After"]) > 0
            body = sick.json()
            assert (body["error"], body["queue"]) == ("unavailable", "ok")
            assert body["database"].startswith("no answer")
            assert body["detail"].startswith("database: no answer")

            throwaway_postgres.start()  # the refused save wrote nothing: version 1 still
            again = client.put("/api/annotate/tracks", json={"version": 1, "tracks": tracks},
                               headers=worker)
            assert again.status_code == 200, again.text
            assert client.get("/healthz").status_code == 200
    finally:
        reset_caches()


def test_healthz_names_the_queue_when_redis_is_down(
        app_env: dict, throwaway_redis: ThrowawayRedis,
        monkeypatch: pytest.MonkeyPatch) -> None:
    from backend.app import create_app

    monkeypatch.setenv("DEXLABEL_REDIS_URL", throwaway_redis.url)
    reset_caches()
    with TestClient(create_app()) as client:
        assert client.get("/healthz").json()["queue"] == "ok"
        throwaway_redis.stop()
        sick = client.get("/healthz")
        assert sick.status_code == 503
        assert sick.json()["database"] == "ok"
        assert sick.json()["detail"].startswith("queue: no answer")
        throwaway_redis.start()
        assert client.get("/healthz").status_code == 200


def test_the_reaper_notices_a_redis_that_lost_its_messages(
        throwaway_redis: ThrowawayRedis) -> None:
    from huey import RedisHuey

    from backend.queue import queue_lost_messages

    queue = RedisHuey("dexlabel", url=throwaway_redis.url, results=False)
    assert queue_lost_messages(queue)  # never marked
    assert not queue_lost_messages(queue)
    throwaway_redis.stop()
    throwaway_redis.start()  # empty: what it held is gone
    assert queue_lost_messages(queue)
    assert not queue_lost_messages(queue)


def _stats_job(url: str) -> tuple[str, bool] | None:
    engine = create_engine(url)
    try:
        with engine.connect() as conn:
            row = conn.execute(text("SELECT status, lease_until IS NOT NULL FROM jobs "
                                    "WHERE kind = 'frame_stats'")).first()
    finally:
        engine.dispose()
    return None if row is None else (str(row[0]), bool(row[1]))


# A worker whose reaper runs every REAP_S seconds instead of every minute, so the test waits
# seconds; the drill (bench/drills.py) measures the real minute.
REAP_S = 3
WORKER = ("import huey.consumer; huey.consumer.Scheduler.periodic_task_seconds = "
          f"{REAP_S}; from backend.cli import app; app(['worker', '--workers', '2'])")


@pytest.mark.slow
def test_a_job_queued_while_redis_is_down_runs_within_a_reaper_pass_of_its_return(
        throwaway_redis: ThrowawayRedis, tmp_path: Path, small_capture: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("DEXLABEL_")}
    env.update({"DEXLABEL_VAR_DIR": str(tmp_path / "var"), "DEXLABEL_ENV": "test",
                "DEXLABEL_REDIS_URL": throwaway_redis.url})
    url = f"sqlite:///{tmp_path / 'var' / 'dexlabel.db'}"
    subprocess.run(CLI + ["migrate"], env=env, check=True, capture_output=True, timeout=120)
    log = tmp_path / "worker.log"
    worker = subprocess.Popen([sys.executable, "-c", WORKER], env=env, stdout=log.open("ab"),
                              stderr=subprocess.STDOUT)
    try:
        time.sleep(2)  # the worker is up and reading the queue
        throwaway_redis.stop()
        imported = subprocess.run(CLI + ["import", str(small_capture)], env=env,
                                  capture_output=True, text=True, timeout=180)
        assert imported.returncode == 0, imported.stderr  # the import itself is committed
        assert _stats_job(url) == ("queued", True), "the unsent message is not recorded"
        time.sleep(2)
        back = time.monotonic()
        throwaway_redis.start()  # empty
        deadline = back + REAP_S + 30
        while (state := _stats_job(url)) != ("done", False) and time.monotonic() < deadline:
            assert worker.poll() is None, log.read_text()[-3000:]
            time.sleep(0.2)
        assert state == ("done", False), (state, log.read_text()[-3000:])
        assert time.monotonic() - back < REAP_S + 20
    finally:
        worker.terminate()
        try:
            worker.wait(timeout=20)
        except subprocess.TimeoutExpired:
            worker.kill()
