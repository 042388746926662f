"""A save racing a forced sequence delete: the delete lands between the save's read of its
assignment and its write, and the save answers 404 in the JSON error shape, never a 500."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import delete, event
from sqlalchemy.orm import ORMExecuteState, Session

from backend.annotation.models import Assignment, Track
from backend.captures.flows import import_path


@pytest.fixture
def hand_link(client: TestClient, admin_headers: dict, small_capture: Path) -> dict:
    seq_id = import_path(small_capture)[0].sequence_id
    tasks = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers).json()
    hand = next(t for t in tasks if t["kind"] == "hand")
    resp = client.post(f"/api/tasks/{hand['id']}/assignments", json={"worker_id": "W1"},
                       headers=admin_headers)
    assert resp.status_code == 200, resp.text
    return resp.json()


@pytest.fixture
def delete_before_the_write(hand_link: dict) -> Iterator[list[str]]:
    """When the save bumps its assignment's version, the assignment and its tracks are gone
    first, as a forced delete committed at that moment leaves them; the statements seen."""
    seen: list[str] = []

    def hook(state: ORMExecuteState) -> Any:
        if state.is_update and not seen and "UPDATE assignments" in str(state.statement):
            seen.append("deleted before the save's write")
            assignment = hand_link["assignment_id"]
            state.session.execute(delete(Track).where(Track.assignment_id == assignment))
            state.session.execute(delete(Assignment).where(Assignment.id == assignment))
        return None

    event.listen(Session, "do_orm_execute", hook)
    yield seen
    event.remove(Session, "do_orm_execute", hook)


def test_a_save_racing_a_forced_delete_is_a_json_404(
    client: TestClient, hand_link: dict, delete_before_the_write: list[str],
) -> None:
    resp = client.put("/api/annotate/tracks", json={"version": 0, "tracks": []},
                      headers={"Authorization": f"Bearer {hand_link['token']}"})
    assert delete_before_the_write == ["deleted before the save's write"]
    assert resp.status_code == 404, resp.text
    assert resp.headers["content-type"].startswith("application/json")
    body = resp.json()
    assert body["error"] == "not_found"
    assert f"assignment {hand_link['assignment_id']}" in body["detail"]
