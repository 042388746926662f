"""Test set-up shared by every test: an isolated var folder, and the real services.

Backends: SQLite always; PostgreSQL and Redis at DEXLABEL_TEST_POSTGRES_URL /
DEXLABEL_TEST_REDIS_URL (defaults: the local servers). When a server is down its tests are
skipped, unless DEXLABEL_TEST_REQUIRE_SERVICES=1 (CI), where that is a failure.
"""

from __future__ import annotations

import os
import tempfile
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

_SESSION_VAR = Path(tempfile.mkdtemp(prefix="dexlabel-test-"))
# Before any backend module is imported: the process-wide defaults point into a temp folder.
os.environ["DEXLABEL_VAR_DIR"] = str(_SESSION_VAR)
os.environ["DEXLABEL_ENV"] = "test"
for _name in ("DEXLABEL_DATABASE_URL", "DEXLABEL_REDIS_URL", "DEXLABEL_STORAGE_URL"):
    os.environ.pop(_name, None)

POSTGRES_URL = os.environ.get(
    "DEXLABEL_TEST_POSTGRES_URL", "postgresql+psycopg://postgres@127.0.0.1:5432/postgres"
)
REDIS_URL = os.environ.get("DEXLABEL_TEST_REDIS_URL", "redis://127.0.0.1:6379/15")
REQUIRE_SERVICES = os.environ.get("DEXLABEL_TEST_REQUIRE_SERVICES") == "1"


def _unavailable(what: str, exc: Exception) -> None:
    message = f"{what} is not reachable: {exc}"
    if REQUIRE_SERVICES:
        pytest.fail(message)
    pytest.skip(message)


@pytest.fixture(scope="session", autouse=True)
def job_handlers() -> None:
    """Every job kind can run here when a test runs a job, as in the commands that run jobs."""
    from worker.tasks import register_handlers

    register_handlers()


@contextmanager
def throwaway_database(prefix: str) -> Iterator[str]:
    """A fresh, empty PostgreSQL database named ``prefix_<random>``, dropped afterwards."""
    from sqlalchemy import create_engine, text
    from sqlalchemy.engine import make_url

    admin_url = make_url(POSTGRES_URL)
    name = f"{prefix}_{uuid.uuid4().hex[:10]}"
    try:
        admin = create_engine(admin_url, isolation_level="AUTOCOMMIT")
        with admin.connect() as conn:
            conn.execute(text(f'CREATE DATABASE "{name}"'))
    except Exception as exc:  # any connection failure means "not reachable"
        _unavailable("PostgreSQL", exc)
    try:
        yield admin_url.set(database=name).render_as_string(hide_password=False)
    finally:
        with admin.connect() as conn:
            conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()


@pytest.fixture(scope="session")
def postgres_server_url() -> Iterator[str]:
    """A fresh, empty PostgreSQL database for this test session (dropped afterwards)."""
    with throwaway_database("dexlabel_test") as url:
        yield url


@pytest.fixture(scope="session")
def redis_url() -> str:
    import redis

    try:
        client = redis.Redis.from_url(REDIS_URL)
        client.ping()
        client.flushdb()
    except Exception as exc:
        _unavailable("Redis", exc)
    return REDIS_URL


def reset_caches() -> None:
    """Forget the cached settings, engine and storage so new env vars take effect."""
    from backend.config import get_settings
    from backend.db import get_engine, get_sessionmaker
    from backend.storage import get_storage

    if get_engine.cache_info().currsize:
        get_engine().dispose()
    for fn in (get_settings, get_engine, get_sessionmaker, get_storage):
        fn.cache_clear()
    from backend.captures.frames import bundle_cache

    bundle_cache.clear()


@pytest.fixture(params=["sqlite", "postgres"])
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    """A migrated-from-nothing database of each kind, empty at the start of the test."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'test.db'}"
        return
    url = request.getfixturevalue("postgres_server_url")
    _drop_all(url)
    yield url
    _drop_all(url)


def _drop_all(url: str) -> None:
    from sqlalchemy import create_engine, text

    engine = create_engine(url)
    with engine.begin() as conn:
        conn.execute(text("DROP SCHEMA public CASCADE; CREATE SCHEMA public"))
    engine.dispose()


@pytest.fixture
def app_env(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, database_url: str) -> Iterator[dict]:
    """Environment of one app instance: its own database (migrated), storage and var folder."""
    from backend.migrate import upgrade

    env = {
        "DEXLABEL_VAR_DIR": str(tmp_path / "var"),
        "DEXLABEL_DATABASE_URL": database_url,
        "DEXLABEL_STORAGE_URL": str(tmp_path / "storage"),
        "DEXLABEL_ENV": "test",
    }
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    reset_caches()
    upgrade(database_url)
    yield env
    reset_caches()


@pytest.fixture(scope="session")
def small_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small synthetic capture (3 views x 6 frames) shared by the import tests; read-only."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("small-capture")
    generate_capture(root, seed=3, frames=6, views=3, objects=2)
    return root


@pytest.fixture(scope="session")
def visibility_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Seed 5, 6 views x 72 frames at 320x240: a hand grasping one object, with its own
    rendered depth maps (a shorter clip interpolates careful keyframes too loosely). Made once
    for the visibility tests of QC and of the backend; read-only."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("visibility-capture")
    generate_capture(root, seed=5, frames=72, views=6, objects=1, width=320, height=240,
                     workers=1)
    return root


@pytest.fixture(scope="session")
def s3_endpoint() -> Iterator[str]:
    """moto's S3 running as a real HTTP server on a free local port."""
    import socket

    from moto.server import ThreadedMotoServer

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)
    server.start()
    yield f"http://127.0.0.1:{port}"
    server.stop()


@pytest.fixture
def s3_bucket(s3_endpoint: str, monkeypatch: pytest.MonkeyPatch) -> str:
    """A new bucket on the moto server; AWS credentials are dummies it accepts."""
    import boto3

    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "testing")
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", "testing")
    name = f"frames-{uuid.uuid4().hex[:8]}"
    boto3.client("s3", endpoint_url=s3_endpoint, region_name="us-east-1").create_bucket(Bucket=name)
    return name
