"""The object highlight of a task: the outline, the frame it holds for and the object's name
as the annotation page says it."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient

from backend.annotation.highlight import OUTLINE_FRAME
from backend.captures.flows import import_path


def test_object_task_highlight_names_its_frame_and_object(
    client: TestClient, admin_headers: dict, small_capture: Path
) -> None:
    sequence_id = import_path(small_capture)[0].sequence_id
    resp = client.post(f"/api/sequences/{sequence_id}/tasks", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    tasks = resp.json()
    highlights = [t["highlight"] for t in tasks if t["kind"] == "object" and t["highlight"]]
    assert highlights, "an object task with an outline"
    for h in highlights:
        assert h["frame"] == OUTLINE_FRAME == 0
        assert len(h["polygon"]) >= 3
        # A YCB name without its number, as the page's refusal says it ("...the highlighted mug").
        assert h["label"] and not h["label"][0].isdigit() and "_" not in h["label"]
