"""Crowd tests: our requester code, through boto3's real client, against the built-in
marketplace served by uvicorn (the marketplace tests' server fixtures, with our settings).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.backend.market.conftest import market_database_url, market_url, migrated_sqlite
from tests.backend.market.helpers import REQUESTERS_SETTING
from tests.conftest import reset_caches

__all__ = ["market_database_url", "market_url", "migrated_sqlite"]

DEV_PAIR = "AKDEXLABELDEVREQUESTER:dexlabel-dev-requester-secret"


@pytest.fixture
def market_env(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, market_database_url: str
) -> Iterator[dict[str, str]]:
    """One app instance whose requester is the built-in marketplace's dev pair (the default)."""
    from backend.market import clock, protocol
    from backend.migrate import upgrade

    env = {
        "DEXLABEL_VAR_DIR": str(tmp_path / "var"),
        "DEXLABEL_DATABASE_URL": market_database_url,
        "DEXLABEL_STORAGE_URL": str(tmp_path / "storage"),
        "DEXLABEL_ENV": "test",
        "DEXLABEL_MARKET_REQUESTERS": f"{REQUESTERS_SETTING},{DEV_PAIR}",
    }
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    for key in ("DEXLABEL_MTURK_ENDPOINT_URL", "DEXLABEL_MTURK_ACCESS_KEY_ID",
                "DEXLABEL_MTURK_SECRET_ACCESS_KEY", "DEXLABEL_PUBLIC_URL"):
        monkeypatch.delenv(key, raising=False)
    reset_caches()
    upgrade(market_database_url)
    yield env
    clock.reset()
    protocol.clear_faults()
    reset_caches()


@pytest.fixture
def crowd_url(market_url: str, monkeypatch: pytest.MonkeyPatch) -> str:
    """The served app's base URL, set as PUBLIC_URL so the crowd client finds /mturk there."""
    from backend.config import get_settings

    monkeypatch.setenv("DEXLABEL_PUBLIC_URL", market_url)
    get_settings.cache_clear()
    return market_url


@pytest.fixture
def tasks(crowd_url: str) -> list[int]:
    """Five annotation tasks (one sequence, five views, one hand each); their ids."""
    from tests.backend.crowd.helpers import make_tasks

    return make_tasks(5)


@pytest.fixture
def mturk(crowd_url: str) -> Any:
    """The requester's boto3 client as the product makes it (botocore retries on)."""
    from backend.config import get_settings
    from backend.crowd.client import make_client

    return make_client(get_settings())


@pytest.fixture
def hit_ids(mturk: Any, tasks: list[int]) -> list[str]:
    """The five tasks published (reward $0.50, fee $0.10, one assignment each); HIT ids."""
    from backend.crowd import flows
    from backend.crowd.schemas import PublishOptions
    from backend.db import session_scope

    with session_scope() as session:
        result = flows.publish(session, mturk, PublishOptions(min_approval_rate=None), None)
    return result.hit_ids


@pytest.fixture
def api(crowd_url: str) -> Iterator[Any]:
    """The app's TestClient, signed in as an admin."""
    from fastapi.testclient import TestClient

    from backend.app import create_app
    from tests.backend.crowd.helpers import admin_headers

    with TestClient(create_app()) as client:
        client.headers.update(admin_headers(client))
        yield client


# ----- Prolific: the provider against the Prolific test double --------------------------------

WEBHOOK_SECRET = "prolific-test-webhook-secret"


@pytest.fixture
def prolific_db_url(market_database_url: str) -> str:
    """The database of a Prolific test (a migrated SQLite copy; a module may override it)."""
    return market_database_url


@pytest.fixture
def prolific(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
             prolific_db_url: str) -> Iterator[Any]:
    """The Prolific double served on loopback, and our settings pointing at it."""
    from backend.migrate import upgrade
    from tests.backend.crowd.prolific_double import TOKEN, ProlificDouble, serve

    double = ProlificDouble()
    double.secret = WEBHOOK_SECRET
    with serve(double.app) as url:
        double.url = url
        env = {"DEXLABEL_VAR_DIR": str(tmp_path / "var"), "DEXLABEL_ENV": "test",
               "DEXLABEL_DATABASE_URL": prolific_db_url,
               "DEXLABEL_STORAGE_URL": str(tmp_path / "storage"),
               "DEXLABEL_PROLIFIC_TOKEN": TOKEN, "DEXLABEL_PROLIFIC_API_URL": url,
               "DEXLABEL_PROLIFIC_WORKSPACE_ID": "ws-test",
               "DEXLABEL_PROLIFIC_WEBHOOK_SECRET": WEBHOOK_SECRET}
        for key, value in env.items():
            monkeypatch.setenv(key, value)
        reset_caches()
        upgrade(prolific_db_url)
        yield double
        reset_caches()


@pytest.fixture
def prolific_provider(prolific: Any) -> Any:
    """Our Prolific provider as ``make`` builds it from the settings."""
    from backend.config import get_settings
    from backend.crowd.providers.prolific import make

    return make(get_settings())
