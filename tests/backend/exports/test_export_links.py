"""Linked frames (symbolic links into the server's storage) come only from the command line:
an HTTP export that asks for them is refused, in any archive, before a job is queued."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import func, select

from backend.db import session_scope
from backend.jobs.models import Job


@pytest.mark.parametrize("archive", ["tar", "zip"])
def test_an_http_export_with_linked_frames_is_refused(
    client: TestClient, admin_headers: dict, archive: str,
) -> None:
    body = {"format": "dexycb", "all": True, "archive": archive, "options": {"frames": "link"}}
    resp = client.post("/api/exports", json=body, headers=admin_headers)
    assert resp.status_code == 422, resp.text
    answer = resp.json()
    assert answer["error"] == "invalid_export" and answer["field"] == "options.frames"
    assert "`dexlabel export --link-frames`" in answer["detail"]
    with session_scope() as session:
        assert session.scalar(select(func.count()).select_from(Job)) == 0
