"""POST /api/assignments/{id}/readonly-link: an admin's link to the annotation page showing one
assignment's saved tracks read-only; its token reads, never writes, and expires within an hour."""

from __future__ import annotations

import base64
import json
import time
from datetime import datetime
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import pytest
from fastapi.testclient import TestClient

from backend.captures.flows import import_path


@pytest.fixture
def tasks(client: TestClient, admin_headers: dict, small_capture: Path) -> list[dict]:
    seq_id = import_path(small_capture)[0].sequence_id
    resp = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    return resp.json()


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _tracks(num_points: int, num_frames: int) -> list[dict]:
    return [{"point": p, "keyframes": [[0, 10.0 + p, 20.0, 1], [2, None, None, 0],
                                       [num_frames - 1, 30.0 + p, 40.0 + p, 1]]}
            for p in range(num_points)]


@pytest.fixture
def saved(client: TestClient, admin_headers: dict, tasks: list[dict]) -> dict:
    """A hand assignment with saved tracks: its link and what was saved."""
    task = next(t for t in tasks if t["kind"] == "hand")
    link = client.post(f"/api/tasks/{task['id']}/assignments", json={"worker_id": "W7"},
                       headers=admin_headers).json()
    tracks = _tracks(task["num_points"], task["num_frames"])
    resp = client.put("/api/annotate/tracks", json={"version": 0, "tracks": tracks},
                      headers=_bearer(link["token"]))
    assert resp.status_code == 200, resp.text
    return {**link, "task": task, "tracks": tracks}


def _readonly(client: TestClient, admin_headers: dict, assignment_id: int) -> tuple[dict, str]:
    resp = client.post(f"/api/assignments/{assignment_id}/readonly-link", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    body = resp.json()
    token = parse_qs(urlsplit(body["url"]).fragment)["token"][0]
    return body, token


def _claims(token: str) -> dict:
    raw = token.split(".")[0]
    return json.loads(base64.urlsafe_b64decode(raw + "=" * (-len(raw) % 4)))


def test_link_opens_the_annotation_page_in_review_mode_with_the_saved_tracks(
    client: TestClient, admin_headers: dict, saved: dict
) -> None:
    body, token = _readonly(client, admin_headers, saved["assignment_id"])
    url = urlsplit(body["url"])
    assert url.path == "/annotate/" and not url.scheme and not url.netloc
    query = parse_qs(url.query)
    assert query["mode"] == ["review"] and query["workerId"] == ["W7"]
    assert query["assignmentId"] == [saved["external_id"]]
    assert "token" not in query  # the token rides in the fragment only
    page = client.get("/api/annotate/task", headers=_bearer(token))
    assert page.status_code == 200, page.text
    data = page.json()
    assert data["mode"] == "review" and data["task"]["id"] == saved["task"]["id"]
    assert data["assignment"]["id"] == saved["assignment_id"]
    assert data["assignment"]["worker_id"] == "W7" and data["assignment"]["version"] == 1
    assert data["assignment"]["tracks"]["tracks"] == saved["tracks"]
    assert client.get(data["frames"]["bundle_url"]).status_code == 200


def test_review_token_cannot_save_or_submit_and_changes_nothing(
    client: TestClient, admin_headers: dict, saved: dict
) -> None:
    _, token = _readonly(client, admin_headers, saved["assignment_id"])
    other = _tracks(21, saved["task"]["num_frames"])
    other[0]["keyframes"][0] = [0, 99.0, 99.0, 1]
    for method, path in (("PUT", "/api/annotate/tracks"), ("POST", "/api/annotate/submit")):
        resp = client.request(method, path, json={"version": 1, "tracks": other},
                              headers=_bearer(token))
        assert resp.status_code == 403, (path, resp.text)
        assert "read-only review" in resp.json()["detail"]
        # Refused for what the token is, before the body is even read.
        bad = client.request(method, path, json={"tracks": "nonsense"}, headers=_bearer(token))
        assert bad.status_code == 403, (path, bad.text)
    worker_view = client.get("/api/annotate/task", headers=_bearer(saved["token"])).json()
    assert worker_view["mode"] == "edit" and worker_view["assignment"]["version"] == 1
    assert worker_view["assignment"]["tracks"]["tracks"] == saved["tracks"]
    # The worker's own link still saves.
    resp = client.put("/api/annotate/tracks", json={"version": 1, "tracks": other},
                      headers=_bearer(saved["token"]))
    assert resp.status_code == 200 and resp.json()["version"] == 2


def test_review_token_expires_within_the_hour(
    client: TestClient, admin_headers: dict, saved: dict
) -> None:
    from backend.annotation.tokens import READONLY_SCOPE
    from backend.config import get_settings
    from backend.security import sign_token

    body, token = _readonly(client, admin_headers, saved["assignment_id"])
    claims = _claims(token)
    assert claims["scope"] == READONLY_SCOPE
    assert 3500 < claims["exp"] - time.time() <= 3600
    expires = datetime.fromisoformat(body["expires_at"]).timestamp()
    assert abs(expires - claims["exp"]) < 5
    stale = sign_token({k: v for k, v in claims.items() if k != "exp"},
                       get_settings().signing_key, -1)
    resp = client.get("/api/annotate/task", headers=_bearer(stale))
    assert resp.status_code == 401 and "expired" in resp.json()["detail"]


def test_a_submitted_assignment_is_shown_for_review_too(
    client: TestClient, admin_headers: dict, saved: dict
) -> None:
    resp = client.post("/api/annotate/submit", json={"version": 1, "tracks": saved["tracks"]},
                       headers=_bearer(saved["token"]))
    assert resp.status_code == 200, resp.text
    _, token = _readonly(client, admin_headers, saved["assignment_id"])
    data = client.get("/api/annotate/task", headers=_bearer(token)).json()
    assert data["mode"] == "review" and data["assignment"]["status"] == "submitted"


def test_unknown_or_malformed_assignment_ids_are_refused_by_name(
    client: TestClient, admin_headers: dict, saved: dict
) -> None:
    resp = client.post("/api/assignments/999999/readonly-link", headers=admin_headers)
    assert resp.status_code == 404 and "assignment 999999" in resp.json()["detail"]
    for bad in ("0", "abc", "-3"):
        resp = client.post(f"/api/assignments/{bad}/readonly-link", headers=admin_headers)
        assert resp.status_code == 422, (bad, resp.text)


def test_only_an_admin_gets_a_link(client: TestClient, admin_headers: dict, saved: dict) -> None:
    path = f"/api/assignments/{saved['assignment_id']}/readonly-link"
    assert client.post(path).status_code == 401
    assert client.post(path, headers=_bearer(saved["token"])).status_code == 401
    _, token = _readonly(client, admin_headers, saved["assignment_id"])
    assert client.post(path, headers=_bearer(token)).status_code == 401
