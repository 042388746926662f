from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.captures.flows import import_path


@pytest.fixture
def tasks(client: TestClient, admin_headers: dict, small_capture: Path) -> list[dict]:
    seq_id = import_path(small_capture)[0].sequence_id
    resp = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    return resp.json()


def _assign(client: TestClient, admin: dict, task_id: int, worker: str = "W1") -> dict:
    resp = client.post(f"/api/tasks/{task_id}/assignments", json={"worker_id": worker},
                       headers=admin)
    assert resp.status_code == 200, resp.text
    return resp.json()


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _full_tracks(num_points: int, num_frames: int) -> list[dict]:
    return [{"point": p, "keyframes": [[0, 10.0 + p, 20.0, 1], [num_frames - 1, 30.0 + p, 40.0, 1]]}
            for p in range(num_points)]


def test_tasks_are_one_per_view_and_target_and_creating_again_adds_none(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    # 3 views x (1 hand + 2 objects)
    assert len(tasks) == 9
    assert sorted(t["kind"] for t in tasks).count("hand") == 3
    hand = next(t for t in tasks if t["kind"] == "hand")
    assert hand["num_points"] == 21 and hand["point_names"][0] == "wrist"
    assert hand["point_names"][4] == "thumb_tip" and len(hand["skeleton"]) == 20
    objects = [t for t in tasks if t["kind"] == "object"]
    assert all(t["num_points"] == 2 for t in objects)
    assert any(t["highlight"] and len(t["highlight"]["polygon"]) >= 3 for t in objects)
    again = client.post(f"/api/sequences/{tasks[0]['sequence_id']}/tasks",
                        headers=admin_headers).json()
    assert sorted(t["id"] for t in again) == sorted(t["id"] for t in tasks)


def test_save_then_read_back_with_versions(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    task = tasks[0]
    link = _assign(client, admin_headers, task["id"])
    page = client.get("/api/annotate/task", headers=_bearer(link["token"])).json()
    assert page["mode"] == "edit" and page["assignment"]["version"] == 0
    assert page["assignment"]["tracks"] is None
    body = {"version": 0, "tracks": _full_tracks(21, 6), "edit_count": 42, "working_time_s": 30.5}
    saved = client.put("/api/annotate/tracks", json=body, headers=_bearer(link["token"]))
    assert saved.status_code == 200 and saved.json()["version"] == 1
    page = client.get("/api/annotate/task", headers=_bearer(link["token"])).json()
    assert page["assignment"]["version"] == 1 and page["assignment"]["edit_count"] == 42
    assert page["assignment"]["tracks"]["tracks"][3]["keyframes"][1] == [5, 33.0, 40.0, 1]


def test_a_stale_save_gets_409_and_changes_nothing(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    link = _assign(client, admin_headers, tasks[0]["id"])
    first = {"version": 0, "tracks": _full_tracks(21, 6)}
    saved = client.put("/api/annotate/tracks", json=first, headers=_bearer(link["token"]))
    assert saved.status_code == 200
    stale = {"version": 0, "tracks": [{"point": 0, "keyframes": [[0, 1.0, 1.0, 1]]}]}
    resp = client.put("/api/annotate/tracks", json=stale, headers=_bearer(link["token"]))
    assert resp.status_code == 409 and resp.json()["current_version"] == 1
    page = client.get("/api/annotate/task", headers=_bearer(link["token"])).json()
    assert page["assignment"]["tracks"]["tracks"][0]["keyframes"][0] == [0, 10.0, 20.0, 1]


@pytest.mark.parametrize(("keyframes", "problem"), [
    ([[0, 700.0, 20.0, 1]], "outside the image"),
    ([[6, 10.0, 20.0, 1]], "frame out of range"),
    ([[0, 10.0, 20.0, 1], [0, 11.0, 20.0, 1]], "duplicate"),
    ([[0, "NaN", 20.0, 1]], "x must be a number"),
    ([[0, 10.0, 20.0]], "expected"),
])
def test_invalid_keyframes_are_refused_with_the_point_named_and_nothing_stored(
    client: TestClient, admin_headers: dict, tasks: list[dict], keyframes: list, problem: str
) -> None:
    link = _assign(client, admin_headers, tasks[0]["id"])
    body = {"version": 0, "tracks": [{"point": 8, "keyframes": keyframes}]}
    resp = client.put("/api/annotate/tracks", json=body, headers=_bearer(link["token"]))
    assert resp.status_code == 422, resp.text
    assert "index_tip" in resp.json()["detail"] and problem in resp.json()["detail"]
    page = client.get("/api/annotate/task", headers=_bearer(link["token"])).json()
    assert page["assignment"]["version"] == 0


def test_non_finite_coordinates_are_refused(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    link = _assign(client, admin_headers, tasks[0]["id"])
    raw = '{"version": 0, "tracks": [{"point": 0, "keyframes": [[0, NaN, 3.0, 1]]}]}'
    resp = client.put("/api/annotate/tracks", content=raw,
                      headers={**_bearer(link["token"]), "Content-Type": "application/json"})
    assert resp.status_code == 422


def test_a_point_the_task_does_not_have_is_refused(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    obj = next(t for t in tasks if t["kind"] == "object")
    link = _assign(client, admin_headers, obj["id"])
    body = {"version": 0, "tracks": _full_tracks(3, 6)}
    resp = client.put("/api/annotate/tracks", json=body, headers=_bearer(link["token"]))
    assert resp.status_code == 422 and "point 2 does not exist" in resp.json()["detail"]


def test_oversized_payload_is_413(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    link = _assign(client, admin_headers, tasks[0]["id"])
    raw = '{"version": 0, "tracks": [], "pad": "' + "x" * 1_100_000 + '"}'
    resp = client.put("/api/annotate/tracks", content=raw,
                      headers={**_bearer(link["token"]), "Content-Type": "application/json"})
    assert resp.status_code == 413


def test_submit_refuses_incomplete_work_frame_by_frame(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    link = _assign(client, admin_headers, tasks[0]["id"])
    tracks = _full_tracks(21, 6)
    tracks[4]["keyframes"] = [[3, 50.0, 50.0, 1]]  # thumb_tip placed from frame 3 only
    resp = client.post("/api/annotate/submit", json={"version": 0, "tracks": tracks},
                       headers=_bearer(link["token"]))
    assert resp.status_code == 422
    body = resp.json()
    assert body["error"] == "incomplete" and "thumb_tip: frames 0-2 not placed" in body["detail"]
    page = client.get("/api/annotate/task", headers=_bearer(link["token"])).json()
    assert page["assignment"]["version"] == 0 and page["assignment"]["status"] == "working"


def test_submit_accepts_complete_work_and_then_freezes_it(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    link = _assign(client, admin_headers, tasks[0]["id"])
    tracks = _full_tracks(21, 6)
    tracks[7]["keyframes"] = [[0, 10.0, 20.0, 1], [2, None, None, 0], [4, 12.0, 22.0, 1]]
    resp = client.post("/api/annotate/submit", json={"version": 0, "tracks": tracks},
                       headers=_bearer(link["token"]))
    assert resp.status_code == 200 and resp.json()["status"] == "submitted"
    page = client.get("/api/annotate/task", headers=_bearer(link["token"])).json()
    assert page["mode"] == "submitted"
    again = client.put("/api/annotate/tracks", json={"version": 1, "tracks": tracks},
                       headers=_bearer(link["token"]))
    assert again.status_code == 409 and "submitted" in again.json()["detail"]


def test_an_assignment_token_opens_nothing_else(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    mine = _assign(client, admin_headers, tasks[0]["id"], "W1")
    other_task = next(t for t in tasks if t["serial"] != tasks[0]["serial"])
    bundle = f"/api/sequences/{other_task['sequence_id']}/views/{other_task['serial']}/frames.bin"
    assert client.get(f"{bundle}?token={mine['token']}").status_code == 401  # not in URLs
    own = client.get("/api/annotate/task", headers=_bearer(mine["token"])).json()
    assert client.get(own["frames"]["bundle_url"]).status_code == 200
    other = own["frames"]["bundle_url"].replace(f"/views/{tasks[0]['serial']}/",
                                               f"/views/{other_task['serial']}/")
    assert client.get(other).status_code == 403  # its view token opens its own view only
    assert client.get("/api/sequences", headers=_bearer(mine["token"])).status_code == 401


def test_a_forged_token_is_refused(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    link = _assign(client, admin_headers, tasks[0]["id"])
    raw, sig = link["token"].split(".")
    forged = raw[:-4] + ("AAAA" if raw[-4:] != "AAAA" else "BBBB") + "." + sig
    resp = client.get("/api/annotate/task", headers=_bearer(forged))
    assert resp.status_code == 401


def test_preview_token_reads_but_cannot_save(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    preview = client.post(f"/api/tasks/{tasks[0]['id']}/preview-token",
                          headers=admin_headers).json()
    assert "ASSIGNMENT_ID_NOT_AVAILABLE" in preview["page_url"]
    page = client.get("/api/annotate/task", headers=_bearer(preview["token"])).json()
    assert page["mode"] == "preview" and page["assignment"] is None
    resp = client.put("/api/annotate/tracks", json={"version": 0, "tracks": []},
                      headers=_bearer(preview["token"]))
    assert resp.status_code == 401 and "accept the HIT" in resp.json()["detail"]


def test_start_takes_only_an_assignment_the_marketplace_can_vouch_for(
    client: TestClient, admin_headers: dict, tasks: list[dict], monkeypatch: pytest.MonkeyPatch
) -> None:
    """No HIT id: refused (direct links are an admin's). A HIT id with no marketplace to ask:
    503 naming it. The genuine and forged starts against a live marketplace are in
    tests/backend/crowd/test_start.py."""
    task_token = client.post(f"/api/tasks/{tasks[0]['id']}/preview-token",
                             headers=admin_headers).json()["token"]
    body = {"task_token": task_token, "assignment_id": "FORGED0001", "worker_id": "NOBODY"}
    forged = client.post("/api/annotate/start", json=body)
    assert forged.status_code == 403 and "no HIT id" in forged.json()["detail"]
    import socket

    from backend.config import get_settings

    with socket.socket() as sock:  # a port nothing listens on: the marketplace is down
        sock.bind(("127.0.0.1", 0))
        monkeypatch.setenv("DEXLABEL_PUBLIC_URL", f"http://127.0.0.1:{sock.getsockname()[1]}")
    get_settings.cache_clear()
    unreachable = client.post("/api/annotate/start", json={**body, "hit_id": "H1"})
    assert unreachable.status_code == 503, unreachable.text
    assert "cannot be checked with the marketplace" in unreachable.json()["detail"]
    preview = client.post("/api/annotate/start",
                          json={**body, "assignment_id": "ASSIGNMENT_ID_NOT_AVAILABLE"})
    assert preview.status_code == 401


def test_admin_box_highlight_is_checked_against_the_image(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    obj = next(t for t in tasks if t["kind"] == "object")
    ok = client.put(f"/api/tasks/{obj['id']}/highlight", json={"box": [10, 20, 100, 120]},
                    headers=admin_headers)
    assert ok.status_code == 200 and ok.json()["highlight"] == {"box": [10.0, 20.0, 100.0, 120.0]}
    bad = client.put(f"/api/tasks/{obj['id']}/highlight", json={"box": [10, 20, 5000, 120]},
                     headers=admin_headers)
    assert bad.status_code == 400 and "box must satisfy" in bad.json()["detail"]


def test_server_produces_the_dense_per_frame_track(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    link = _assign(client, admin_headers, tasks[0]["id"])
    tracks = _full_tracks(21, 6)
    tracks[0]["keyframes"] = [[1, 10.0, 20.0, 1], [3, 20.0, 40.0, 0]]
    client.put("/api/annotate/tracks", json={"version": 0, "tracks": tracks},
               headers=_bearer(link["token"]))
    dense = client.get(f"/api/assignments/{link['assignment_id']}/dense",
                       headers=admin_headers).json()
    wrist = dense["points"][0]
    assert wrist["state"] == ["unplaced", "keyframe", "interpolated", "keyframe",
                              "interpolated", "interpolated"]
    assert wrist["xy"][0] == [None, None] and wrist["xy"][2] == [15.0, 30.0]
    assert wrist["visible"] == [False, True, True, False, False, False]


def test_a_save_racing_a_submit_from_another_tab_is_refused_and_changes_nothing(
    client: TestClient, admin_headers: dict, tasks: list[dict]
) -> None:
    from sqlalchemy.orm.attributes import set_committed_value

    from backend.annotation.models import Assignment
    from backend.annotation.schemas import TracksSave
    from backend.annotation.service import get_assignment_or_raise, save_tracks
    from backend.db import get_sessionmaker, session_scope
    from backend.errors import Conflict

    link = _assign(client, admin_headers, tasks[0]["id"])
    body = {"version": 0, "tracks": _full_tracks(21, 6)}
    assert client.post("/api/annotate/submit", json=body,
                       headers=_bearer(link["token"])).status_code == 200
    # This tab read the assignment while it was still being worked on ...
    session = get_sessionmaker()()
    try:
        stale = get_assignment_or_raise(session, link["assignment_id"])
        set_committed_value(stale, "status", "working")  # before the other tab submitted
        later = TracksSave.model_validate({"version": 1, "tracks": _full_tracks(21, 6)[:1]})
        with pytest.raises(Conflict, match="assignment is submitted"):
            save_tracks(session, stale, later)
    finally:
        session.rollback()
        session.close()
    with session_scope() as s:
        stored = s.get(Assignment, link["assignment_id"])
        assert stored is not None and stored.status == "submitted" and stored.version == 1
        assert len(stored.tracks) == 21
