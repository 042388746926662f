"""Progress you can see: each task's state follows its work (published, submitted, in review,
accepted; open where nothing is on offer), in the API and in `dexlabel status`."""

from __future__ import annotations

from pathlib import Path

import httpx
from sqlalchemy import select
from typer.testing import CliRunner

from backend.db import session_scope
from tests.backend.pipeline.test_pipeline import _confirm, _drain
from tests.backend.quality.helpers import (
    ADMIN_EMAIL,
    ADMIN_PASSWORD,
    crowd_submits,
    publish_hand_tasks,
)


def _progress(base: str, sequence_id: int) -> tuple[int, dict]:
    from backend.crowd.simulate import admin_token

    with httpx.Client(timeout=30.0) as http:
        token = admin_token(http, base, ADMIN_EMAIL, ADMIN_PASSWORD)
        resp = http.get(f"{base}/api/sequences/{sequence_id}/progress",
                        headers={"Authorization": f"Bearer {token}"})
    return resp.status_code, resp.json()


def _expected_states() -> dict[int, str]:
    """Each task's state worked out here from the rows, independently of the product's query."""
    from backend.annotation.models import Assignment, Task
    from backend.crowd.models import CrowdHit
    from backend.quality.models import QCReport

    expected = {}
    with session_scope() as session:
        for task in session.scalars(select(Task)):
            work = list(session.scalars(select(Assignment).where(Assignment.task_id == task.id)))
            reported = set(session.scalars(select(QCReport.assignment_id)))
            live = session.scalar(select(CrowdHit.id).where(
                CrowdHit.task_id == task.id, CrowdHit.expired_at.is_(None)))
            if any(a.status == "approved" for a in work):
                expected[task.id] = "accepted"
            elif any(a.status == "submitted" and a.id in reported for a in work):
                expected[task.id] = "in review"
            elif any(a.status == "submitted" for a in work):
                expected[task.id] = "submitted"
            elif live or any(a.status == "working" for a in work):
                expected[task.id] = "published"
            else:
                expected[task.id] = "open"
    return expected


def test_task_states_follow_the_work_in_the_api_and_the_cli(
        crowd_url: str, qc_capture: Path) -> None:
    from backend.cli import app

    sequence_id, hits = publish_hand_tasks(qc_capture, max_assignments=1)
    status, body = _progress(crowd_url, sequence_id)
    assert status == 200
    states = {t["task_id"]: t["state"] for t in body["tasks"]}
    hand = {t["task_id"] for t in body["tasks"] if t["kind"] == "hand"}
    assert len(hand) == len(hits) == 6 and len(body["views"]) == 6
    assert body["targets"][0] == "hand:0" and len(body["targets"]) == 2
    # Published hand tasks; object tasks not published are open.
    assert {states[t] for t in hand} == {"published"}
    assert {s for t, s in states.items() if t not in hand} == {"open"}
    assert (body["state"], body["hits"], body["hits_live"]) == ("in progress", 6, 6)
    assert body["solve"] is None

    outcomes = crowd_submits(crowd_url, qc_capture, ["careful"] * 3 + ["spammer"])
    assert [o.status for o in outcomes] == ["submitted"] * 4
    _, body = _progress(crowd_url, sequence_id)
    assert body["counts"]["submitted"] == 4 and body["assignments"]["submitted"] == 4
    assert {t["task_id"]: t["state"] for t in body["tasks"]} == _expected_states()

    _confirm(outcomes)
    _drain()
    _, body = _progress(crowd_url, sequence_id)
    after = {t["task_id"]: t["state"] for t in body["tasks"]}
    assert after == _expected_states()
    # Every submission is scored now: none is left "submitted"; the careful work is
    # accepted (or waits for review), the spammer's is rejected and its task open again
    # once its HIT is used up, or still published while the HIT takes more work.
    assert body["counts"]["submitted"] == 0
    assert body["counts"]["accepted"] + body["counts"]["in review"] >= 3
    assert body["assignments"]["rejected"] >= 1
    assert sum(body["counts"].values()) == len(body["tasks"]) == 12

    runner = CliRunner()
    result = runner.invoke(app, ["status", str(sequence_id)])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0].startswith(f"{sequence_id}  ") and "in progress: 12 tasks" in lines[0]
    assert f"{body['counts']['accepted']} accepted" in lines[0] or not body["counts"]["accepted"]
    assert "solve: none yet" in lines[0]
    start = lines.index("") + 1
    grid = lines[start:lines.index("", start)]  # the cost per labelled 3D frame follows
    assert lines[lines.index("", start) + 1].startswith("cost per labelled 3D frame (no solve")
    assert grid[0].split() == ["view", "hand:0", "object:0"]
    by_cell = {(t["serial"], t["target_key"]): t["state"] for t in body["tasks"]}
    for row in grid[1:]:
        serial, rest = row.split(None, 1)
        hand_state = by_cell[(serial, "hand:0")]
        assert rest.startswith(hand_state), (row, hand_state)
        assert rest.rstrip().endswith(by_cell[(serial, "object:0")]), row

    listing = runner.invoke(app, ["status"])
    assert listing.exit_code == 0 and listing.output.splitlines()[0] == lines[0]


def test_progress_of_a_sequence_that_does_not_exist_is_an_error(
        crowd_url: str, qc_capture: Path) -> None:
    from backend.cli import app

    publish_hand_tasks(qc_capture, max_assignments=1)
    status, body = _progress(crowd_url, 999)
    assert status == 404 and "sequence 999 does not exist" in str(body)
    result = CliRunner().invoke(app, ["status", "999"])
    assert result.exit_code == 2
    assert result.output.startswith("error: no sequence 999")
