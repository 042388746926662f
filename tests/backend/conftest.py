"""Fixtures of the API tests: an app with one admin, and that admin's bearer header."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from backend.db import session_scope

ADMIN_EMAIL = "admin@example.org"
ADMIN_PASSWORD = "correct horse battery"


@pytest.fixture
def client(app_env: dict) -> Iterator[TestClient]:
    from backend.accounts.service import create_admin
    from backend.app import create_app

    with session_scope() as s:
        create_admin(s, ADMIN_EMAIL, ADMIN_PASSWORD)
    with TestClient(create_app()) as c:
        yield c


@pytest.fixture
def admin_headers(client: TestClient) -> dict[str, str]:
    resp = client.post("/api/auth/token", json={"email": ADMIN_EMAIL, "password": ADMIN_PASSWORD})
    assert resp.status_code == 200, resp.text
    return {"Authorization": f"Bearer {resp.json()['access_token']}"}
