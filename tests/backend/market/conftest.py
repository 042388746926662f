"""Marketplace tests: boto3's real ``mturk`` client against the real app served by uvicorn.

Every test gets its own database (a copy of one migrated SQLite file; the backend modules
swap in the parametrised SQLite/PostgreSQL ``database_url``) and its own server on a free
port, in a thread of this process, so tests can also move the marketplace clock and call
the worker-side service functions directly.
"""

from __future__ import annotations

import shutil
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.backend.market.helpers import REQUESTERS_SETTING, MTurk, make_client
from tests.conftest import reset_caches


@pytest.fixture(scope="session")
def migrated_sqlite(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One SQLite file migrated to head; each test copies it instead of migrating again."""
    from backend.migrate import upgrade

    path = tmp_path_factory.mktemp("market-template") / "market.db"
    upgrade(f"sqlite:///{path}")
    return path


@pytest.fixture
def market_database_url(tmp_path: Path, migrated_sqlite: Path) -> str:
    target = tmp_path / "market.db"
    shutil.copyfile(migrated_sqlite, target)
    return f"sqlite:///{target}"


@pytest.fixture
def market_env(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, market_database_url: str
) -> Iterator[dict[str, str]]:
    """Settings of one marketplace instance: its own database and the test requesters."""
    from backend.market import clock, protocol
    from backend.migrate import upgrade

    env = {
        "DEXLABEL_VAR_DIR": str(tmp_path / "var"),
        "DEXLABEL_DATABASE_URL": market_database_url,
        "DEXLABEL_STORAGE_URL": str(tmp_path / "storage"),
        "DEXLABEL_ENV": "test",
        "DEXLABEL_MARKET_REQUESTERS": REQUESTERS_SETTING,
    }
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    reset_caches()
    upgrade(market_database_url)
    yield env
    clock.reset()
    protocol.clear_faults()
    reset_caches()


@pytest.fixture
def market_url(market_env: dict[str, str]) -> Iterator[str]:
    """Base URL of the app, served by uvicorn in a background thread."""
    import uvicorn

    from backend.app import create_app

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    config = uvicorn.Config(create_app(), log_level="warning", lifespan="off")
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    deadline = time.monotonic() + 10
    while not server.started:
        assert thread.is_alive() and time.monotonic() < deadline, "uvicorn did not start"
        time.sleep(0.005)
    yield f"http://127.0.0.1:{port}"
    server.should_exit = True
    thread.join(timeout=10)
    sock.close()


@pytest.fixture
def mturk(market_url: str) -> MTurk:
    """The requester's boto3 mturk client (no retries: each error is seen as it happens)."""
    return make_client(market_url)
