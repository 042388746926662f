"""Keyframe provenance through the annotation API: a save stores each keyframe's source (the 5th
element of a row, only when it is not "placed"), the page reads it back, submit accepts it, and a
row with an unknown source or of the wrong length is refused 422 by name, storing nothing."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.captures.flows import import_path

NUM_FRAMES = 6  # the small capture's clip


@pytest.fixture
def hand_token(client: TestClient, admin_headers: dict, small_capture: Path) -> str:
    """The token of a fresh assignment of the small capture's first hand task."""
    seq_id = import_path(small_capture)[0].sequence_id
    tasks = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers).json()
    hand = next(t for t in tasks if t["kind"] == "hand")
    assert hand["num_frames"] == NUM_FRAMES
    resp = client.post(f"/api/tasks/{hand['id']}/assignments", json={"worker_id": "W1"},
                       headers=admin_headers)
    assert resp.status_code == 200, resp.text
    return str(resp.json()["token"])


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _stored(client: TestClient, token: str) -> dict:
    """The assignment as the page reads it."""
    resp = client.get("/api/annotate/task", headers=_bearer(token))
    assert resp.status_code == 200, resp.text
    return dict(resp.json()["assignment"])


def _mixed_tracks() -> list[dict]:
    """21 complete tracks; point 1 carries every source, the others are placed."""
    tracks = [{"point": p, "keyframes": [[0, 10.0 + p, 20.0, 1], [5, 30.0 + p, 40.0, 1]]}
              for p in range(21)]
    tracks[1]["keyframes"] = [
        [0, 11.0, 20.0, 1, "placed"],
        [1, 12.0, 21.0, 1, "tracked"],
        [2, 13.0, 22.0, 0, "edited"],
        [3, None, None, 0, "prefilled"],
        [5, 31.0, 40.0, 1],
    ]
    return tracks


def test_sources_are_stored_and_read_back_in_the_short_form(
    client: TestClient, hand_token: str
) -> None:
    body = {"version": 0, "tracks": _mixed_tracks()}
    saved = client.put("/api/annotate/tracks", json=body, headers=_bearer(hand_token))
    assert saved.status_code == 200, saved.text
    tracks = _stored(client, hand_token)["tracks"]["tracks"]
    by_point = {t["point"]: t["keyframes"] for t in tracks}
    assert by_point[1] == [
        [0, 11.0, 20.0, 1],  # "placed" is the default and is not written
        [1, 12.0, 21.0, 1, "tracked"],
        [2, 13.0, 22.0, 0, "edited"],
        [3, None, None, 0, "prefilled"],
        [5, 31.0, 40.0, 1],
    ]
    assert by_point[0] == [[0, 10.0, 20.0, 1], [5, 30.0, 40.0, 1]]


def test_a_save_with_sources_can_be_submitted(client: TestClient, hand_token: str) -> None:
    body = {"version": 0, "tracks": _mixed_tracks()}
    resp = client.post("/api/annotate/submit", json=body, headers=_bearer(hand_token))
    assert resp.status_code == 200, resp.text
    assignment = _stored(client, hand_token)
    assert assignment["status"] == "submitted"
    assert assignment["tracks"]["tracks"][1]["keyframes"][1] == [1, 12.0, 21.0, 1, "tracked"]


ALLOWED = "source must be one of placed, tracked, prefilled, edited, got"


@pytest.mark.parametrize(("row", "problem"), [
    ([3, 12.0, 21.0, 1, "guessed"], f"index_tip: keyframe 1 (frame 3): {ALLOWED} 'guessed'"),
    ([3, 12.0, 21.0, 1, "Tracked"], f"{ALLOWED} 'Tracked'"),
    ([3, 12.0, 21.0, 1, 2], f"{ALLOWED} 2"),
    ([3, 12.0, 21.0, 1, "tracked", 0], "index_tip: keyframe 1 (frame 3): expected"),
])
def test_an_unknown_source_or_a_six_element_row_is_refused_by_name(
    client: TestClient, hand_token: str, row: list, problem: str
) -> None:
    first = {"version": 0, "tracks": _mixed_tracks()}
    assert client.put("/api/annotate/tracks", json=first, headers=_bearer(hand_token)).is_success
    body = {"version": 1, "tracks": [{"point": 8, "keyframes": [[0, 1.0, 1.0, 1], row]}]}
    resp = client.put("/api/annotate/tracks", json=body, headers=_bearer(hand_token))
    assert resp.status_code == 422, resp.text
    assert problem in resp.json()["detail"]
    # Nothing of the refused save is stored.
    assignment = _stored(client, hand_token)
    assert assignment["version"] == 1
    assert assignment["tracks"]["tracks"][8]["keyframes"] == [[0, 18.0, 20.0, 1],
                                                              [5, 38.0, 40.0, 1]]
