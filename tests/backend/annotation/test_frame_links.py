"""The annotation page's frame links carry a read-only view token of one view, valid for an
hour, never the page's own (write-capable) token; a frame URL with any other token is
refused."""

from __future__ import annotations

import json
import time
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import pytest
from fastapi.testclient import TestClient

from backend.annotation.tokens import FRAME_TOKEN_TTL_S
from backend.captures.flows import import_path
from backend.security import _unb64


@pytest.fixture
def task(client: TestClient, admin_headers: dict, small_capture: Path) -> dict:
    seq_id = import_path(small_capture)[0].sequence_id
    resp = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers)
    assert resp.status_code == 200, resp.text
    return resp.json()[0]


def _token_of(url: str) -> str:
    return parse_qs(urlsplit(url).query)["token"][0]


def _payload(token: str) -> dict:
    return json.loads(_unb64(token.split(".")[0]))


@pytest.mark.parametrize("link", ["assignment", "preview"])
def test_frame_links_carry_a_short_lived_view_token_only(
    client: TestClient, admin_headers: dict, task: dict, link: str
) -> None:
    if link == "assignment":
        page_token = client.post(f"/api/tasks/{task['id']}/assignments", headers=admin_headers,
                                 json={"worker_id": "W1"}).json()["token"]
    else:
        page_token = client.post(f"/api/tasks/{task['id']}/preview-token",
                                 headers=admin_headers).json()["token"]
    page = client.get("/api/annotate/task", headers={"Authorization": f"Bearer {page_token}"})
    assert page.status_code == 200, page.text
    frames = page.json()["frames"]
    for url in (frames["bundle_url"], frames["manifest_url"]):
        token = _token_of(url)
        assert token != page_token and page_token not in url
        claims = _payload(token)
        assert claims["scope"] == "view"
        assert (claims["sequence_id"], claims["serial"]) == (task["sequence_id"], task["serial"])
        assert claims["exp"] - time.time() <= FRAME_TOKEN_TTL_S + 5
    assert client.get(frames["bundle_url"]).status_code == 200
    manifest = client.get(frames["manifest_url"])
    assert manifest.status_code == 200
    assert page_token not in manifest.text
    # The page's own token in a frame URL opens nothing.
    base = frames["bundle_url"].split("?")[0]
    refused = client.get(f"{base}?token={page_token}")
    assert refused.status_code == 401 and "not valid for view" in refused.json()["detail"]
