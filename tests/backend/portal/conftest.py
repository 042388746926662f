"""Portal API tests: the real app served by uvicorn (the marketplace tests' fixtures), the
requester on boto3's real mturk client, the worker on the portal's HTTP API. The portal page
itself is tested in Chromium in tests/browser/test_portal.py."""

from __future__ import annotations

from dataclasses import dataclass

import httpx
import pytest

from tests.backend.market.conftest import (
    market_database_url,
    market_env,
    market_url,
    migrated_sqlite,
    mturk,
)

# The marketplace tests' fixtures, used here by name.
__all__ = ["market_database_url", "market_env", "market_url", "migrated_sqlite", "mturk"]

ADMIN_EMAIL = "portal-admin@example.org"
ADMIN_PASSWORD = "portal admin password"
WORKER_PASSWORD = "worker password 1"


@dataclass
class Portal:
    """The portal API at ``base``, with the admin's bearer header."""

    base: str
    admin_headers: dict[str, str]

    def call(self, method: str, path: str, token: str | None = None,
             json: dict | None = None) -> httpx.Response:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.request(method, f"{self.base}/api/portal{path}", json=json,
                             headers=headers, timeout=10)

    def ok(self, method: str, path: str, token: str | None = None, json: dict | None = None):
        resp = self.call(method, path, token, json)
        assert resp.status_code == 200, resp.text
        return resp.json()

    def new_worker(self, email: str) -> dict:
        """An admin-created account, logged in: its login reply (access_token, worker_id)."""
        resp = httpx.post(f"{self.base}/api/portal/workers", headers=self.admin_headers,
                          json={"email": email, "password": WORKER_PASSWORD}, timeout=10)
        assert resp.status_code == 200, resp.text
        return self.ok("POST", "/login", json={"email": email, "password": WORKER_PASSWORD})


@pytest.fixture
def portal(market_url: str) -> Portal:
    from backend.accounts.service import create_admin
    from backend.db import session_scope

    with session_scope() as session:
        create_admin(session, ADMIN_EMAIL, ADMIN_PASSWORD)
    resp = httpx.post(f"{market_url}/api/auth/token", timeout=10,
                      json={"email": ADMIN_EMAIL, "password": ADMIN_PASSWORD})
    assert resp.status_code == 200, resp.text
    return Portal(market_url, {"Authorization": f"Bearer {resp.json()['access_token']}"})
