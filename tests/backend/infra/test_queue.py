"""The job queue end to end: a real `dexlabel import` enqueues, a real `dexlabel worker` runs.

Two deployments: the embedded one (SQLite database, SQLite queue, local files) and the
scale-out one (PostgreSQL, Redis queue, S3 storage on moto's HTTP server).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from sqlalchemy import create_engine, text

from tests.conftest import _drop_all

CLI = [sys.executable, "-m", "backend.cli"]


def _run(args: list[str], env: dict[str, str]) -> str:
    proc = subprocess.run(CLI + args, env=env, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, f"dexlabel {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout


def _stats_done(url: str) -> tuple[int, int]:
    engine = create_engine(url)
    try:
        with engine.connect() as conn:
            total = conn.execute(text("SELECT count(*) FROM frames")).scalar_one()
            done = conn.execute(text(
                "SELECT count(*) FROM frames WHERE stats IS NOT NULL AND thumb_key IS NOT NULL"
            )).scalar_one()
    finally:
        engine.dispose()
    return done, total


def _import_then_work(env: dict[str, str], capture: Path, url: str) -> None:
    _run(["migrate"], env)
    out = _run(["import", str(capture)], env)
    assert "imported" in out and "3 cameras x 6 frames" in out
    assert _stats_done(url) == (0, 18), "no worker runs yet, so no statistics yet"
    worker = subprocess.Popen(CLI + ["worker", "--workers", "2"], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline and _stats_done(url)[0] < 18:
            assert worker.poll() is None, f"worker exited early:\n{worker.stdout.read()}"
            time.sleep(0.3)
        assert _stats_done(url) == (18, 18)
    finally:
        worker.send_signal(signal.SIGINT)
        try:
            worker.wait(timeout=20)
        except subprocess.TimeoutExpired:
            worker.kill()


def _base_env(tmp_path: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("DEXLABEL_")}
    env.update({"DEXLABEL_VAR_DIR": str(tmp_path / "var"), "DEXLABEL_ENV": "test"})
    return env


def test_embedded_queue_runs_the_frame_statistics_job(tmp_path: Path, small_capture: Path) -> None:
    env = _base_env(tmp_path)
    url = f"sqlite:///{tmp_path / 'var' / 'dexlabel.db'}"
    _import_then_work(env, small_capture, url)
    thumbs = list((tmp_path / "var" / "storage").rglob("thumb_*.jpg"))
    assert len(thumbs) == 18


def test_redis_queue_runs_the_job_with_postgres_and_s3(
    tmp_path: Path, small_capture: Path, postgres_server_url: str, redis_url: str,
    s3_endpoint: str, s3_bucket: str,
) -> None:
    import boto3

    _drop_all(postgres_server_url)
    env = _base_env(tmp_path)
    env.update({
        "DEXLABEL_DATABASE_URL": postgres_server_url,
        "DEXLABEL_REDIS_URL": redis_url,
        "DEXLABEL_STORAGE_URL": f"s3://{s3_bucket}/dx",
        "DEXLABEL_S3_ENDPOINT_URL": s3_endpoint,
        "AWS_ACCESS_KEY_ID": "testing",
        "AWS_SECRET_ACCESS_KEY": "testing",
    })
    _import_then_work(env, small_capture, postgres_server_url)
    s3 = boto3.client("s3", endpoint_url=s3_endpoint, region_name="us-east-1")
    keys = [o["Key"] for o in s3.list_objects_v2(Bucket=s3_bucket, Prefix="dx/")["Contents"]]
    assert sum("/thumb_" in k for k in keys) == 18
    assert not (tmp_path / "var" / "queue.db").exists(), "the Redis deployment must not use SQLite"
    _drop_all(postgres_server_url)
