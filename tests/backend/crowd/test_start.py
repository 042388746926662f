"""The annotation page opens a marketplace assignment only when the marketplace vouches for it
(``POST /api/annotate/start``): the HIT is this task's and a worker holds an assignment of it,
or the marketplace's record of the assignment names that HIT and worker. A forged start is
refused naming why; work the marketplace never confirmed is never scored."""

from __future__ import annotations

import socket
from typing import Any
from urllib.parse import parse_qs, urlsplit

import httpx
import pytest
from sqlalchemy import select

from backend.config import get_settings
from backend.db import session_scope
from tests.backend.market.helpers import accept, submit

TRACKS = [{"point": p, "keyframes": [[0, 10.0 + p, 20.0, 1], [5, 30.0 + p, 40.0, 1]]}
          for p in range(21)]


def _task_of(hit_id: str) -> int:
    from backend.crowd.models import CrowdHit

    with session_scope() as session:
        task_id = session.scalar(select(CrowdHit.task_id).where(CrowdHit.hit_id == hit_id))
        assert task_id is not None
        return int(task_id)


def _task_token(mturk: Any, hit_id: str) -> str:
    """The task token of the HIT's page, as the worker's browser gets it."""
    question = mturk.get_hit(HITId=hit_id)["HIT"]["Question"]
    url = question.split("<ExternalURL>")[1].split("</ExternalURL>")[0].replace("&amp;", "&")
    return parse_qs(urlsplit(url).query)["task"][0]


def _start(base: str, task_token: str, assignment_id: str, worker_id: str,
           hit_id: str | None) -> httpx.Response:
    body = {"task_token": task_token, "assignment_id": assignment_id, "worker_id": worker_id}
    if hit_id is not None:
        body["hit_id"] = hit_id
    return httpx.post(f"{base}/api/annotate/start", json=body, timeout=30)


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def test_a_worker_who_holds_the_assignment_starts_it_and_opens_it_again(
    crowd_url: str, mturk: Any, hit_ids: list[str]
) -> None:
    hit_id = hit_ids[0]
    token = _task_token(mturk, hit_id)
    market_id = accept(hit_id, "AWORKERGENUINE01")
    first = _start(crowd_url, token, market_id, "AWORKERGENUINE01", hit_id)
    assert first.status_code == 200, first.text
    page = httpx.get(f"{crowd_url}/api/annotate/task", headers=_bearer(first.json()["token"]),
                     timeout=30).json()
    assert page["mode"] == "edit" and page["assignment"]["external_id"] == market_id
    again = _start(crowd_url, token, market_id, "AWORKERGENUINE01", hit_id)
    assert again.status_code == 200
    reopened = httpx.get(f"{crowd_url}/api/annotate/task", timeout=30,
                         headers=_bearer(again.json()["token"])).json()
    assert reopened["assignment"]["id"] == page["assignment"]["id"]
    thief = _start(crowd_url, token, market_id, "AWORKERTHIEF0001", hit_id)
    assert thief.status_code == 403 and "another task, worker or HIT" in thief.json()["detail"]


def test_a_forged_start_is_refused_naming_why(
    crowd_url: str, mturk: Any, hit_ids: list[str]
) -> None:
    from backend.annotation.models import Assignment

    hit_id, other_hit = hit_ids[0], hit_ids[1]
    token = _task_token(mturk, hit_id)
    # The probe: the HIT page's task token, no HIT id, made-up ids.
    no_hit = _start(crowd_url, token, "FORGED0001", "NOBODY", None)
    assert no_hit.status_code == 403, no_hit.text
    assert "no HIT id" in no_hit.json()["detail"]
    assert "POST /api/tasks/{id}/assignments" in no_hit.json()["detail"]
    # A real HIT of this task that nobody holds.
    unheld = _start(crowd_url, token, "FORGED0001", "NOBODY", hit_id)
    assert unheld.status_code == 403 and "no worker holds" in unheld.json()["detail"]
    # A HIT the marketplace does not have.
    missing = _start(crowd_url, token, "FORGED0001", "NOBODY", "3XFORGEDHIT00000000000000000X")
    assert missing.status_code == 404 and "has no HIT" in missing.json()["detail"]
    # Another task's HIT, held by a worker.
    accept(other_hit, "AWORKEROTHER0001")
    crossed = _start(crowd_url, token, "FORGED0001", "NOBODY", other_hit)
    assert crossed.status_code == 403 and "not a HIT of this task" in crossed.json()["detail"]
    # A real submitted assignment, claimed by someone else.
    market_id = accept(hit_id, "AWORKERREAL00001")
    assert submit(crowd_url, market_id, labels="ok").status_code == 200
    claimed = _start(crowd_url, token, market_id, "NOBODY", hit_id)
    assert claimed.status_code == 403 and "is not worker NOBODY's" in claimed.json()["detail"]
    with session_scope() as session:
        assert session.scalars(select(Assignment)).all() == [], "nothing was started"


def test_a_marketplace_that_cannot_be_reached_answers_503(
    crowd_url: str, mturk: Any, hit_ids: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    token = _task_token(mturk, hit_ids[0])
    market_id = accept(hit_ids[0], "AWORKERGENUINE02")
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        dead = f"http://127.0.0.1:{sock.getsockname()[1]}"
    monkeypatch.setenv("DEXLABEL_PUBLIC_URL", dead)  # the requester endpoint is {dead}/mturk
    get_settings.cache_clear()
    resp = _start(crowd_url, token, market_id, "AWORKERGENUINE02", hit_ids[0])
    assert resp.status_code == 503, resp.text
    assert resp.headers["Retry-After"]
    detail = resp.json()["detail"]
    assert "cannot be checked with the marketplace" in detail and dead in detail


def test_work_the_marketplace_never_confirmed_is_not_scored(
    crowd_url: str, mturk: Any, hit_ids: list[str]
) -> None:
    """A made-up assignment id started on a HIT while a real worker holds one of it gets in
    (the requester API cannot name the holder before submission) and takes the held slot
    until the HIT's assignment duration has passed; its work never enters the consensus:
    only work the marketplace confirmed is scored."""
    from datetime import timedelta

    from sqlalchemy import update

    from backend.annotation.models import Assignment
    from backend.crowd.client import make_client
    from backend.db import utcnow
    from backend.pipeline import sync
    from backend.quality.inputs import target_inputs

    hit_id = hit_ids[0]
    token = _task_token(mturk, hit_id)
    market_id = accept(hit_id, "AWORKERGENUINE03")
    forged = _start(crowd_url, token, "FORGEDWHILEHELD1", "NOBODY", hit_id)
    assert forged.status_code == 200
    refused = _start(crowd_url, token, market_id, "AWORKERGENUINE03", hit_id)
    assert refused.status_code == 403 and "no open slot" in refused.json()["detail"]
    duration = mturk.get_hit(HITId=hit_id)["HIT"]["AssignmentDurationInSeconds"]
    with session_scope() as session:  # the forged start has expired
        session.execute(update(Assignment).where(Assignment.external_id == "FORGEDWHILEHELD1")
                        .values(created_at=utcnow() - timedelta(seconds=duration + 60)))
    genuine = _start(crowd_url, token, market_id, "AWORKERGENUINE03", hit_id)
    assert genuine.status_code == 200, genuine.text
    for started in (forged, genuine):
        done = httpx.post(f"{crowd_url}/api/annotate/submit", timeout=30,
                          headers=_bearer(started.json()["token"]),
                          json={"version": 0, "tracks": TRACKS})
        assert done.status_code == 200 and done.json()["status"] == "submitted", done.text
    assert submit(crowd_url, market_id, labels="ok").status_code == 200
    with session_scope() as session:
        assert sync(session, make_client(get_settings())).accepted == 1
    with session_scope() as session:
        ids = {a.external_id: a.id for a in session.scalars(select(Assignment))}
        task = session.get_one(Assignment, ids[market_id]).task
        scored = target_inputs(session, task.sequence_id, task.target_key)
        assert set(scored.who) == {str(ids[market_id])}
    assert _task_of(hit_id) == task.id
