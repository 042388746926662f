"""The autosave's write path: what a save stores, and how a malformed body is answered."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from backend.annotation.models import Track
from backend.captures.flows import import_path
from backend.db import session_scope


@pytest.fixture
def hand_link(client: TestClient, admin_headers: dict, small_capture: Path) -> dict:
    seq_id = import_path(small_capture)[0].sequence_id
    tasks = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers).json()
    hand = next(t for t in tasks if t["kind"] == "hand")
    resp = client.post(f"/api/tasks/{hand['id']}/assignments", json={"worker_id": "W1"},
                       headers=admin_headers)
    assert resp.status_code == 200, resp.text
    return {**resp.json(), "num_frames": hand["num_frames"]}


def _stored(assignment_id: int) -> dict[int, list]:
    with session_scope() as s:
        tracks = s.scalars(select(Track).where(Track.assignment_id == assignment_id))
        return {t.point_index: t.keyframes for t in tracks}


def _put(client: TestClient, link: dict, body: dict):  # type: ignore[no-untyped-def]
    return client.put("/api/annotate/tracks", json=body,
                      headers={"Authorization": f"Bearer {link['token']}"})


def test_a_save_stores_each_points_rows_in_their_stored_form(
    client: TestClient, hand_link: dict
) -> None:
    last = hand_link["num_frames"] - 1
    sent = [
        {"point": 0, "keyframes": [[0, 10, 20, 1], [last, 30.25, 40.5, True, "placed"]]},
        {"point": 3, "keyframes": [[0, None, None, 0], [1, 5.5, 6.5, False, "tracked"],
                                   [last, 7.0, 8.0, 1, "edited"]]},
        {"point": 20, "keyframes": [[2, 1e-3, 479.5, 1, "prefilled"]]},
    ]
    expected = {0: [[0, 10.0, 20.0, 1], [last, 30.25, 40.5, 1]],
                3: [[0, None, None, 0], [1, 5.5, 6.5, 0, "tracked"], [last, 7.0, 8.0, 1, "edited"]],
                20: [[2, 0.001, 479.5, 1, "prefilled"]]}
    first = _put(client, hand_link, {"version": 0, "tracks": sent})
    assert first.status_code == 200, first.text
    stored = _stored(hand_link["assignment_id"])
    assert stored == {p: expected.get(p, []) for p in range(21)}
    # Saved again over existing rows: every point replaced, one left out emptied.
    again = [{"point": 3, "keyframes": [[4, 1.5, 2.5, 1]]},
             {"point": 7, "keyframes": [[0, 100, 200, 0, "edited"]]}]
    second = _put(client, hand_link, {"version": 1, "tracks": again})
    assert second.status_code == 200 and second.json()["version"] == 2
    stored = _stored(hand_link["assignment_id"])
    assert stored == {p: {3: [[4, 1.5, 2.5, 1]], 7: [[0, 100.0, 200.0, 0, "edited"]]}.get(p, [])
                      for p in range(21)}
    assert all(type(row[1]) is float for rows in stored.values() for row in rows)
    page = client.get("/api/annotate/task",
                      headers={"Authorization": f"Bearer {hand_link['token']}"}).json()
    assert page["assignment"]["tracks"]["tracks"][7]["keyframes"] == [[0, 100.0, 200.0, 0,
                                                                       "edited"]]


def test_a_full_save_of_every_point_and_frame_round_trips(
    client: TestClient, hand_link: dict
) -> None:
    frames = hand_link["num_frames"]
    tracks = [{"point": p,
               "keyframes": [[f, 0.5 + p + f / 3, 479.25 - p, 1] for f in range(frames)]}
              for p in range(21)]
    for version in (0, 1):
        assert _put(client, hand_link, {"version": version, "tracks": tracks}).status_code == 200
    stored = _stored(hand_link["assignment_id"])
    assert stored == {t["point"]: t["keyframes"] for t in tracks}


@pytest.mark.parametrize(("keyframes", "field", "message"), [
    ([[0, 1.0, 2.0, 1], 5], ["body", "tracks", 0, "keyframes", 1], "Input should be a valid list"),
    ({"0": [0, 1.0, 2.0, 1]}, ["body", "tracks", 0, "keyframes"], "Input should be a valid list"),
    ([[0, 1.0, 2.0, 1]] * 2001, ["body", "tracks", 0, "keyframes"],
     "List should have at most 2000 items after validation, not 2001"),
], ids=["row-not-a-list", "rows-not-a-list", "too-many-rows"])
def test_malformed_keyframe_lists_are_refused_by_name_and_store_nothing(
    client: TestClient, hand_link: dict, keyframes: object, field: list, message: str
) -> None:
    resp = _put(client, hand_link, {"version": 0, "tracks": [{"point": 0, "keyframes": keyframes}]})
    assert resp.status_code == 422, resp.text
    name = ".".join(str(part) for part in field[1:])
    assert resp.json()["fields"] == [{"field": name, "message": message}]
    assert resp.json()["detail"] == f"{name}: {message}"
    assert _stored(hand_link["assignment_id"]) == {}


def _put_raw(client: TestClient, link: dict, body: bytes):  # type: ignore[no-untyped-def]
    return client.put("/api/annotate/tracks", content=body,
                      headers={"Authorization": f"Bearer {link['token']}",
                               "Content-Type": "application/json"})


def test_a_body_that_is_not_json_gets_the_json_error_it_always_got(
    client: TestClient, hand_link: dict
) -> None:
    resp = _put_raw(client, hand_link, b'{"version": 0, "tracks": [')
    assert resp.status_code == 422, resp.text
    # Python's json module's own position and words.
    assert resp.json()["detail"] == "body: invalid JSON at character 26: Expecting value"
    assert _stored(hand_link["assignment_id"]) == {}


@pytest.mark.parametrize(("body", "field", "words"), [
    # JSON that the fast parser refuses but Python's json module reads: the save's own checks
    # still name the problem.
    (b'{"version": 0, "tracks": [{"point": 0, "keyframes": [[0, NaN, 2.0, 1]]}]}',
     None, "wrist: keyframe 0"),
    (b'{"version": 0, "tracks": [{"point": 0, "keyframes": [[0, Infinity, 2.0, 1]]}]}',
     None, "wrist: keyframe 0"),
    (b'{"version": 18446744073709551616, "tracks": []}', "version", "less than or equal"),
])
def test_json_only_the_standard_library_reads_is_checked_as_before(
    client: TestClient, hand_link: dict, body: bytes, field: str | None, words: str
) -> None:
    resp = _put_raw(client, hand_link, body)
    assert resp.status_code == 422, resp.text
    if field is not None:
        assert resp.json()["fields"][0]["field"] == field
    assert words in resp.json()["detail"]
    assert _stored(hand_link["assignment_id"]) == {}
