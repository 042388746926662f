"""POST /api/annotate/stretches: the page's check before submit. On a fast synthetic clip, a
track keyed every 4th frame is told which stretches the images say it does not follow, in
words; the careful worker who keys where the path bends gets (almost) none."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient

from backend.captures.flows import import_path
from tests.backend.annotation.test_annotation_proposals import _bearer, _truth, fast_capture  # noqa: F401

URL = "/api/annotate/stretches"


def _warnings(client: TestClient, admin_headers: dict, capture: Path, follow: bool) -> list:
    from worker.synth.annotators import annotate

    seq_id = import_path(capture)[0].sequence_id
    task = next(t for t in client.post(f"/api/sequences/{seq_id}/tasks",
                                       headers=admin_headers).json() if t["kind"] == "hand")
    token = client.post(f"/api/tasks/{task['id']}/assignments", json={"worker_id": "W1"},
                        headers=admin_headers).json()["token"]
    truth, visible = _truth(capture, task["serial"], task["num_frames"])
    work = annotate(truth, visible, (640, 480), "careful", np.random.default_rng(3),
                    follow_motion=follow)
    body = {"tracks": [{"point": p, "keyframes": rows} for p, rows in enumerate(work.tracks)]}
    resp = client.post(URL, json=body, headers=_bearer(token))
    assert resp.status_code == 200, resp.text
    assert resp.json()["checked_frames"] == task["num_frames"]
    return list(resp.json()["warnings"])


def test_keys_every_fourth_frame_through_fast_motion_are_warned_in_words(
    client: TestClient, admin_headers: dict, fast_capture: Path  # noqa: F811
) -> None:
    sparse = _warnings(client, admin_headers, fast_capture, follow=False)
    assert len(sparse) >= 20
    worst = sparse[0]
    assert worst["offset_px"] >= max(w["offset_px"] for w in sparse) - 1e-9
    first, last = worst["frames"]
    said = re.fullmatch(r"(\w+ \w+) moves (\d+) px between frames (\d+) and (\d+) that the "
                        r"track does not follow", worst["message"])
    assert said is not None, worst["message"]
    assert abs(int(said[2]) - worst["offset_px"]) <= 1
    assert [int(said[3]), int(said[4])] == [first, last]
    careful = _warnings(client, admin_headers, fast_capture, follow=True)
    assert len(careful) <= len(sparse) / 5


def test_bad_keyframes_are_refused_by_name(client: TestClient, admin_headers: dict,
                                           fast_capture: Path) -> None:  # noqa: F811
    seq_id = import_path(fast_capture)[0].sequence_id
    task = next(t for t in client.post(f"/api/sequences/{seq_id}/tasks",
                                       headers=admin_headers).json() if t["kind"] == "hand")
    token = client.post(f"/api/tasks/{task['id']}/assignments", json={"worker_id": "W1"},
                        headers=admin_headers).json()["token"]
    resp = client.post(URL, json={"tracks": [{"point": 0, "keyframes": [[99, 1.0, 1.0, 1]]}]},
                       headers=_bearer(token))
    assert resp.status_code == 422 and "99" in resp.text
    assert client.post(URL, json={"tracks": []}).status_code == 401
