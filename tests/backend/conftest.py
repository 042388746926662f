"""Fixtures of the backend tests: an app with one admin and that admin's bearer header; the
synthetic captures the QC, pipeline and progress tests share."""

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


@pytest.fixture(scope="session")
def qc_capture(tmp_path_factory: pytest.TempPathFactory):
    """A synthetic capture with enough views and frames for a consensus (6 views x 16 frames,
    320x240 to keep it quick)."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("qc-capture")
    generate_capture(root, seed=5, frames=16, views=6, objects=1, width=320, height=240)
    return root


@pytest.fixture(scope="session")
def training_capture(tmp_path_factory: pytest.TempPathFactory):
    """A clip as long as the real ones relative to its size (2 views x 48 frames, 320x240): a
    careful worker's keyframe interpolation stays within a few pixels of the gold."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("training-capture")
    generate_capture(root, seed=6, frames=48, views=2, objects=1, width=320, height=240)
    return root
