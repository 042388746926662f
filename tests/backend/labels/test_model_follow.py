"""POST /api/annotate/model-follow: the hand model followed through a first view's depth from a
worker's keyframes, through the real app and the real job queue's handler.

The capture: seed 5, 2 views rendered at the default clips' pace (72 frames), cut to its
first FRAMES frames before import (each followed frame takes about a second of CPU). A careful
worker keys the hand of view 1 on frame 0 (2 px click noise); the proposals are compared with
the view's true joints.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from fastapi.testclient import TestClient

from backend.captures.flows import import_path
from backend.db import session_scope

URL = "/api/annotate/model-follow"
FRAMES = 10
VIEW = 1


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _cut(root: Path, frames: int) -> None:
    """Keep a synthetic capture's first ``frames`` frames (files, meta.yml, pose.npz)."""
    for meta in root.rglob("meta.yml"):
        seq = meta.parent
        data = yaml.safe_load(meta.read_text())
        data["num_frames"] = frames
        meta.write_text(yaml.safe_dump(data))
        with np.load(seq / "pose.npz") as pose:
            kept = {k: pose[k][:frames] for k in pose.files}
        np.savez(seq / "pose.npz", **kept)
        for path in seq.glob("*/*_[0-9][0-9][0-9][0-9][0-9][0-9].*"):
            if int(path.stem.rsplit("_", 1)[1]) >= frames:
                path.unlink()


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("model-follow-capture")
    generate_capture(root, seed=5, frames=72, views=2, objects=1, workers=1)
    _cut(root, FRAMES)
    return root


@pytest.fixture
def view(client: TestClient, admin_headers: dict, capture: Path) -> dict:
    """View 1's hand task, two workers' links of it, its truth, and the object task."""
    from backend.captures.truth import CaptureTruth
    from worker.synth.annotators import hand_visibility

    seq_id = import_path(capture)[0].sequence_id
    tasks = client.post(f"/api/sequences/{seq_id}/tasks", headers=admin_headers).json()
    hand = [t for t in tasks if t["kind"] == "hand"][VIEW]
    obj = next(t for t in tasks if t["kind"] == "object")
    links = [client.post(f"/api/tasks/{hand['id']}/assignments", json={"worker_id": w},
                         headers=admin_headers).json() for w in ("M1", "M2")]
    joint_2d, seg = CaptureTruth(capture).view(hand["serial"], FRAMES)
    return {"task": hand, "object": obj, "links": links, "truth": joint_2d,
            "visible": hand_visibility(joint_2d, seg)}


def _first_frame_keys(view: dict, seed: int = 0, frame: int = 0) -> dict:
    """A careful worker's keyframes of one frame: visible joints clicked with 2 px noise, the
    others keyed occluded."""
    truth, visible = view["truth"][frame], view["visible"][frame]
    noisy = truth + np.random.default_rng(seed).normal(0.0, 2.0, truth.shape)
    return {"tracks": [{"point": p, "keyframes": [
        [frame, round(float(noisy[p, 0]), 2), round(float(noisy[p, 1]), 2), 1]
        if visible[p] else [frame, None, None, 0]]} for p in range(21)]}


def _post(client: TestClient, token: str, body: dict, status: int = 200) -> dict:
    resp = client.post(URL, json=body, headers=_bearer(token))
    assert resp.status_code == status, resp.text
    return resp.json()


def _jobs() -> list[tuple[str, str]]:
    from sqlalchemy import select

    from backend.jobs.models import Job
    from backend.labels.model_follow import MODEL_FOLLOW_KIND

    with session_scope() as session:
        return [(j.key, j.status) for j in session.scalars(
            select(Job).where(Job.kind == MODEL_FOLLOW_KIND).order_by(Job.id))]


def _run_jobs() -> int:
    """Run the queued follow jobs here, as a queue worker would; how many ran."""
    from backend.jobs.runner import execute
    from worker.tasks import register_handlers

    register_handlers()
    queued = [key for key, status in _jobs() if status == "queued"]
    for key in queued:
        execute(key)
    return len(queued)


def _grid(points: list[dict]) -> np.ndarray:
    rows = [[[np.nan, np.nan] if v is None else v for v in p["xy"]] for p in points]
    return np.swapaxes(np.array(rows, dtype=float), 0, 1)


def test_a_first_view_is_followed_by_one_queued_job_close_to_the_truth(
        client: TestClient, view: dict) -> None:
    from backend.config import get_settings
    from worker.assist.checks import check_cells, check_key

    link, body = view["links"][0], _first_frame_keys(view)
    first = _post(client, link["token"], body)
    assert first["available"] is False and first["preparing"] is True
    assert "following the hand" in first["reason"]
    # Asked again (the page polls): the same job, not a second.
    assert _post(client, link["token"], body)["preparing"] is True
    (job,) = _jobs()
    assert job[1] == "queued" and job[0].startswith(f"model_follow:{view['task']['id']}:")
    assert _run_jobs() == 1
    answer = _post(client, link["token"], body)
    assert answer["available"] is True and answer["preparing"] is False
    assert answer["start_frame"] == 0 and answer["min_joints"] == 6
    assert {(s["direction"], s["reached"]) for s in answer["stops"]} >= {("backward", 0)}
    xy, ok = _grid(answer["points"]), np.array([p["ok"] for p in answer["points"]]).T
    truth, visible = view["truth"], view["visible"]
    # Never at the worker's own keyframes; only where its keyframes have the joint visible
    # (a joint keyed occluded stays so until the worker keys it again).
    assert not ok[0].any()
    assert not ok[:, ~visible[0]].any()
    later = np.zeros(visible.shape, bool)
    later[1:] = visible[1:] & visible[0]
    assert (ok & later).sum() >= 0.8 * later.sum(), answer["stops"]
    cells = set(check_cells(check_key(get_settings().signing_key), link["assignment_id"], 21,
                            FRAMES))
    planted = np.zeros(ok.shape, bool)
    for point, frame in cells:
        planted[frame, point] = ok[frame, point]
    err = np.linalg.norm(xy - truth, axis=-1)
    assert np.median(err[ok & ~planted]) < 2.5, np.median(err[ok & ~planted])
    # The check cells are shown 15 px off the follow, as in every proposal.
    other = _post(client, view["links"][1]["token"], body)
    moved = np.linalg.norm(_grid(other["points"]) - xy, axis=-1)
    theirs = set(check_cells(check_key(get_settings().signing_key),
                             view["links"][1]["assignment_id"], 21, FRAMES))
    for point, frame in cells ^ theirs:
        if ok[frame, point]:
            assert moved[frame, point] == pytest.approx(15.0, abs=2e-3)
    # The other worker's ask found the stored follow: no job of its own.
    assert len(_jobs()) == 1


def test_asked_again_from_a_corrected_frame_it_follows_on_forward_from_there(
        client: TestClient, view: dict) -> None:
    """The page's second ask (backend.crowd.simulate.PageAssistance, as the page sends it):
    every keyframe, the first follow's accepted rows too, with frame CORRECTED keyed again
    where the worker sees the joints, and ``begin`` there: proposals only after it."""
    from backend.crowd.simulate import PageAssistance, WorkerClient

    corrected = 5
    link, body = view["links"][0], _first_frame_keys(view)
    task = {"num_frames": FRAMES, "width": 640, "height": 480, "kind": "hand"}
    page = PageAssistance(WorkerClient(client, ""), link["token"], task, poll_s=0.01,
                          poll_limit_s=0.05)
    anchors = [t["keyframes"] for t in body["tracks"]]
    page.model_follow(anchors)
    assert _run_jobs() == 1
    xy, ok = page.model_follow(anchors)
    fix = _first_frame_keys(view, seed=3, frame=corrected)["tracks"]
    accepted = [[*rows, *([f, *[round(float(v), 2) for v in xy[f, p]], 1]
                          for f in range(1, corrected) if ok[f, p]), *fix[p]["keyframes"]]
                for p, rows in enumerate(anchors)]
    assert page.model_follow(accepted, begin=corrected)[1].sum() == 0  # queued
    assert _run_jobs() == 1
    again, held = page.model_follow(accepted, begin=corrected)
    visible = view["visible"]
    assert not held[:corrected + 1].any()
    after = visible[corrected + 1:] & visible[corrected]
    assert held[corrected + 1:][after].mean() >= 0.8
    err = np.linalg.norm(again - view["truth"], axis=-1)[held]
    assert np.median(err) < 2.5, np.median(err)
    # The page's status names the corrected frame as where the rings start, though the
    # follow was carried there from frame 0.
    answer = _post(client, link["token"], {"tracks": [
        {"point": p, "keyframes": rows} for p, rows in enumerate(accepted)],
        "begin": corrected})
    assert answer["available"] is True and answer["start_frame"] == corrected


def test_other_keyframes_wait_for_the_follow_under_way(client: TestClient, view: dict) -> None:
    token = view["links"][0]["token"]
    assert _post(client, token, _first_frame_keys(view, seed=1))["preparing"] is True
    answer = _post(client, token, _first_frame_keys(view, seed=2))
    assert answer["preparing"] is True and "earlier keyframes" in answer["reason"]
    assert [status for _, status in _jobs()] == ["queued"]


def test_what_the_model_cannot_start_from_is_said(client: TestClient, view: dict) -> None:
    token = view["links"][0]["token"]
    body = _first_frame_keys(view)
    few = {"tracks": body["tracks"][:5]}
    answer = _post(client, token, few)
    assert answer["available"] is False and answer["preparing"] is False
    assert answer["reason"].startswith("place at least 6 visible joints on one frame")
    assert _jobs() == []
    # Keyframes that are not one hand: the joints' numbers shuffled.
    shuffled = {"tracks": [{"point": t["point"], "keyframes": body["tracks"][20 - i]["keyframes"]}
                           for i, t in enumerate(body["tracks"])]}
    _post(client, token, shuffled)
    _run_jobs()
    answer = _post(client, token, shuffled)
    assert answer["available"] is False and "could not start from frame 0" in answer["reason"]


def test_a_view_without_depth_is_told_so(client: TestClient, view: dict) -> None:
    from backend.captures.models import Camera

    with session_scope() as session:
        session.get_one(Camera, _camera_id(view["task"]["id"])).has_depth = False
    answer = _post(client, view["links"][0]["token"], _first_frame_keys(view))
    assert answer["available"] is False
    assert answer["reason"] == "this view has no depth maps: the hand model cannot follow it"


def _camera_id(task_id: int) -> int:
    from backend.annotation.models import Task

    with session_scope() as session:
        return session.get_one(Task, task_id).camera_id


def test_bad_requests_are_refused_naming_the_problem(
        client: TestClient, admin_headers: dict, view: dict) -> None:
    token = view["links"][0]["token"]
    body = _first_frame_keys(view)
    resp = client.post(URL, json={**body, "begin": FRAMES}, headers=_bearer(token))
    assert resp.status_code == 422 and f"begin {FRAMES} is out of range" in resp.text
    resp = client.post(URL, json={"tracks": [{"point": 30, "keyframes": [[0, 1, 1, 1]]}]},
                       headers=_bearer(token))
    assert resp.status_code == 422 and "point 30 does not exist" in resp.text
    resp = client.post(URL, json={"tracks": [{"point": 0, "keyframes": [[FRAMES, 1, 1, 1]]}]},
                       headers=_bearer(token))
    assert resp.status_code == 422
    assert client.post(URL, json={**body, "extra": 1}, headers=_bearer(token)).status_code \
        == 422
    obj = client.post(f"/api/tasks/{view['object']['id']}/assignments",
                      json={"worker_id": "M3"}, headers=admin_headers).json()
    resp = client.post(URL, json={"tracks": []}, headers=_bearer(obj["token"]))
    assert resp.status_code == 422 and "hand tasks only" in resp.text
    # Who may ask: an assignment's own token; not a preview, a review link or no one.
    assert client.post(URL, json=body).status_code == 401
    preview = client.post(f"/api/tasks/{view['task']['id']}/preview-token",
                          headers=admin_headers).json()["token"]
    assert client.post(URL, json=body, headers=_bearer(preview)).status_code == 401
    review = client.post(f"/api/assignments/{view['links'][0]['assignment_id']}/readonly-link",
                         headers=admin_headers).json()["url"].split("#token=")[1]
    assert client.post(URL, json=body, headers=_bearer(review)).status_code == 403
    assert _jobs() == []


def test_the_simulated_crowds_page_asks_the_route_as_the_page_does(
        client: TestClient, admin_headers: dict, view: dict) -> None:
    """backend.crowd.simulate.PageAssistance.model_follow: the same body, the answer as
    (F, P, 2) and (F, P); polled while preparing; nothing on an object page."""
    from backend.crowd.simulate import PageAssistance, WorkerClient

    link, body = view["links"][0], _first_frame_keys(view)
    anchors = [t["keyframes"] for t in body["tracks"]]
    task = {"num_frames": FRAMES, "width": 640, "height": 480, "kind": "hand"}
    page = PageAssistance(WorkerClient(client, ""), link["token"], task, poll_s=0.01,
                          poll_limit_s=0.05)
    xy, ok = page.model_follow(anchors)  # still preparing when it gives up: nothing shown
    assert xy.shape == (FRAMES, 21, 2) and not ok.any()
    assert _run_jobs() == 1
    xy, ok = page.model_follow(anchors)
    answer = _post(client, link["token"], body)
    np.testing.assert_array_equal(ok, np.array([p["ok"] for p in answer["points"]]).T)
    np.testing.assert_array_equal(xy[ok], _grid(answer["points"])[ok])
    assert ok.sum() > 100
    for kind, model in (("object", True), ("hand", False)):
        other = PageAssistance(WorkerClient(client, ""), link["token"], {**task, "kind": kind},
                               model=model)
        assert other.model_follow(anchors) is None
