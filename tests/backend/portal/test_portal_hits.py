"""The worker portal's HIT list for published dexlabel tasks: titles that tell the tasks apart,
the task named in each row, a thumbnail of the view's first frame behind a token of its own,
and the HITs a worker accepted or submitted marked for that worker only."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np
import pytest
from sqlalchemy import select

from backend.annotation.models import Task
from backend.config import get_settings
from backend.crowd.client import make_client
from backend.crowd.models import CrowdHit
from backend.crowd.publish import publish_task
from backend.crowd.schemas import PublishOptions
from backend.crowd.titles import MAX_TITLE_CHARS, TaskFacts, hit_title, object_label
from backend.db import session_scope
from backend.security import sign_token
from tests.backend.crowd import conftest as crowd_fixtures
from tests.backend.crowd.helpers import ADMIN_EMAIL, ADMIN_PASSWORD
from tests.backend.market.helpers import create_hit, external_question, submit
from tests.backend.portal.conftest import Portal

# The crowd tests' served app (its requester is the built-in marketplace's dev pair), in place
# of this folder's marketplace fixtures of the same names.
crowd_url = crowd_fixtures.crowd_url
market_env = crowd_fixtures.market_env

FRAMES = 6  # small_capture: 3 views x 6 frames, one right hand and two objects


@pytest.fixture
def published(crowd_url: str, small_capture: Path) -> dict[str, dict[str, Any]]:
    """Every task of the capture published; per HIT id: task id, kind, target, serial and the
    view's name ("camera 2 of 3", in the sequence's camera order)."""
    from backend.accounts.service import create_admin
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.captures.models import Hand, SceneObject
    from backend.storage import get_storage

    sequence_id = import_path(small_capture)[0].sequence_id
    with session_scope() as session:
        create_admin(session, ADMIN_EMAIL, ADMIN_PASSWORD)
        task_ids = [t.id for t in create_tasks(session, get_storage(), sequence_id)]
    client, found = make_client(get_settings()), {}
    for task_id in task_ids:
        with session_scope() as session, session.no_autoflush:
            task = session.get_one(Task, task_id)
            hit_id = publish_task(session, client, task, PublishOptions(min_approval_rate=None),
                                  [])[0]
            if task.kind == "hand":
                target = f"{session.get_one(Hand, task.hand_id).side} hand"
            else:
                target = object_label(session.get_one(SceneObject, task.object_id).name)
            cameras = task.sequence.cameras
            found[hit_id] = {"task_id": task_id, "kind": task.kind, "target": target,
                             "serial": task.camera.serial,
                             "view_name": f"camera {cameras.index(task.camera) + 1} of "
                                          f"{len(cameras)}"}
    return found


@pytest.fixture
def portal(crowd_url: str) -> Portal:
    resp = httpx.post(f"{crowd_url}/api/auth/token", timeout=10,
                      json={"email": ADMIN_EMAIL, "password": ADMIN_PASSWORD})
    assert resp.status_code == 200, resp.text
    return Portal(crowd_url, {"Authorization": f"Bearer {resp.json()['access_token']}"})


def test_each_hit_title_names_its_target_view_and_frame_count(
    published: dict[str, dict[str, Any]], small_capture: Path,
) -> None:
    client = make_client(get_settings())
    titles = {h["HITId"]: h["Title"] for h in client.list_hits(MaxResults=100)["HITs"]}
    serials = sorted(p.name for p in small_capture.glob("*/*/*") if p.is_dir())
    assert sorted({p["serial"] for p in published.values()}) == serials
    assert {p["target"] for p in published.values()} >= {"right hand"}
    for hit_id, task in published.items():
        assert titles[hit_id] == (f"Track the {task['target']} · {task['view_name']} · "
                                  f"{FRAMES} frames")
        assert task["serial"] not in titles[hit_id]
        assert len(titles[hit_id]) <= MAX_TITLE_CHARS
    assert len(set(titles.values())) == len(published) == 9


def test_a_long_object_name_is_shortened_to_keep_the_title_within_mturks_limit() -> None:
    facts = TaskFacts(kind="object", target="very long object name " * 10, serial="800007060125",
                      num_frames=72, sequence_id=1, view_number=3, num_views=8)
    title = hit_title(facts)
    assert len(title) == MAX_TITLE_CHARS
    assert title.startswith("Track the very long object name")
    assert title.endswith("… · camera 3 of 8 · 72 frames")
    assert object_label("006_mustard_bottle") == "mustard bottle"


def test_the_list_marks_the_hits_a_worker_accepted_or_submitted_for_that_worker_only(
    published: dict[str, dict[str, Any]], portal: Portal,
) -> None:
    amy, ben = portal.new_worker("amy@example.org"), portal.new_worker("ben@example.org")
    first = portal.ok("GET", "/hits?mine=true", amy["access_token"])
    assert len(first) == 9 and all(h["mine"] is None and h["can_accept"] for h in first)
    for row in first:
        task = published[row["hit_id"]]
        assert row["task"] == {"kind": task["kind"], "target": task["target"],
                               "view": task["serial"], "view_name": task["view_name"],
                               "frames": FRAMES}
    taken, done = first[4]["hit_id"], first[6]["hit_id"]
    held = portal.ok("POST", f"/hits/{taken}/accept", amy["access_token"])
    finished = portal.ok("POST", f"/hits/{done}/accept", amy["access_token"])
    assert submit(portal.base, finished["assignment_id"], result="submitted:1").status_code == 200

    mine = portal.ok("GET", "/hits?mine=true", amy["access_token"])
    assert (mine[0]["hit_id"], mine[0]["mine"], mine[0]["can_accept"]) == (
        taken, {"assignment_id": held["assignment_id"], "status": "Accepted"}, False)
    assert (mine[-1]["hit_id"], mine[-1]["mine"]) == (
        done, {"assignment_id": finished["assignment_id"], "status": "Submitted"})
    assert [h["mine"] for h in mine[1:-1]] == [None] * 7 and len(mine) == 9
    # The plain list still shows only what the worker can take.
    plain = {h["hit_id"] for h in portal.ok("GET", "/hits", amy["access_token"])}
    assert plain == set(published) - {taken, done}
    # Ben sees neither mark: one assignment per HIT, both are amy's.
    bens = portal.ok("GET", "/hits?mine=true", ben["access_token"])
    assert {h["hit_id"] for h in bens} == set(published) - {taken, done}
    assert all(h["mine"] is None for h in bens)


def _decode(data: bytes) -> np.ndarray:
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert image is not None
    return image.astype(float)


def _first_frame(task_id: int) -> np.ndarray:
    from backend.captures import service as captures
    from backend.storage import get_storage

    with session_scope() as session:
        task = session.get_one(Task, task_id)
        frame = captures.get_frame_or_raise(session, task.sequence_id, task.camera.serial, 0)
        return _decode(get_storage().get_bytes(frame.color_key))


def test_the_thumbnail_is_the_views_first_frame_made_small(
    published: dict[str, dict[str, Any]], portal: Portal,
) -> None:
    amy = portal.new_worker("amy@example.org")
    rows = portal.ok("GET", "/hits", amy["access_token"])
    by_view = {published[r["hit_id"]]["serial"]: r for r in rows if r["task"]["kind"] == "hand"}
    assert len(by_view) == 3
    for serial, row in by_view.items():
        resp = httpx.get(portal.base + row["thumbnail_url"], timeout=10)  # no bearer header
        assert resp.status_code == 200, resp.text
        assert resp.headers["content-type"] == "image/jpeg" and len(resp.content) < 20_000
        thumb = _decode(resp.content)
        frames = {s: _first_frame(published[r["hit_id"]]["task_id"]) for s, r in by_view.items()}
        full = frames[serial]
        assert thumb.shape[1] == 160
        assert abs(thumb.shape[0] - full.shape[0] * 160 / full.shape[1]) <= 1
        errors = {s: float(np.abs(cv2.resize(f, thumb.shape[1::-1], interpolation=cv2.INTER_AREA)
                                  - thumb).mean()) for s, f in frames.items()}
        assert errors[serial] < 3.0, errors  # JPEG noise only
        assert all(errors[serial] < e for s, e in errors.items() if s != serial), errors
        assert thumb.std() > 5  # a picture, not a blank


def test_a_thumbnail_opens_only_with_its_own_hits_token(
    published: dict[str, dict[str, Any]], portal: Portal,
) -> None:
    amy = portal.new_worker("amy@example.org")
    rows = portal.ok("GET", "/hits", amy["access_token"])
    one, other = rows[0]["hit_id"], rows[1]["hit_id"]
    good = rows[0]["thumbnail_url"].split("token=")[1]
    path = f"{portal.base}/api/portal/hits/{one}/thumbnail.jpg"

    def get(url: str, token: str | None) -> httpx.Response:
        return httpx.get(url, params={} if token is None else {"token": token}, timeout=10)

    missing = get(path, None)
    assert missing.status_code == 401 and "token" in missing.text
    assert get(path, good).status_code == 200
    wrong_hit = get(f"{portal.base}/api/portal/hits/{other}/thumbnail.jpg", good)
    assert wrong_hit.status_code == 403 and "another HIT" in wrong_hit.text
    key = get_settings().signing_key
    expired = sign_token({"scope": "portal-thumbnail", "hit_id": one}, key, -1)
    assert "expired" in get(path, expired).text and get(path, expired).status_code == 401
    assert get(path, good[:-3] + "AAA").status_code == 401
    # Neither the worker's own token nor a view token opens it ...
    assert get(path, amy["access_token"]).status_code == 401
    task = published[one]
    with session_scope() as session:
        sequence_id = session.get_one(Task, task["task_id"]).sequence_id
    view = sign_token({"scope": "view", "sequence_id": sequence_id, "serial": task["serial"]},
                      key, 60)
    assert get(path, view).status_code == 401
    # ... and the thumbnail token opens nothing else: not the frames, not the worker's API.
    frame = f"{portal.base}/api/sequences/{sequence_id}/views/{task['serial']}/frames/0.jpg"
    assert get(frame, good).status_code == 401
    assert portal.call("GET", "/hits", good).status_code == 401
    assert portal.call("POST", f"/hits/{one}/accept", good).status_code == 401


def test_a_hit_that_is_not_a_dexlabel_task_has_no_task_and_no_thumbnail(
    published: dict[str, dict[str, Any]], portal: Portal,
) -> None:
    client = make_client(get_settings())
    foreign = create_hit(client, Title="A survey",
                         Question=external_question("https://survey.example.org/?task=x", 600))
    amy = portal.new_worker("amy@example.org")
    row = next(r for r in portal.ok("GET", "/hits", amy["access_token"])
               if r["hit_id"] == foreign["HITId"])
    assert (row["title"], row["task"], row["thumbnail_url"]) == ("A survey", None, None)
    with session_scope() as session:
        assert session.scalar(select(CrowdHit).where(CrowdHit.hit_id == foreign["HITId"])) is None
    key = get_settings().signing_key
    token = sign_token({"scope": "portal-thumbnail", "hit_id": foreign["HITId"]}, key, 60)
    resp = httpx.get(f"{portal.base}/api/portal/hits/{foreign['HITId']}/thumbnail.jpg",
                     params={"token": token}, timeout=10)
    assert resp.status_code == 404 and "not a dexlabel task" in resp.text
