"""The start reply says how the page completes, as the provider that published the HIT says:
MTurk's externalSubmit form for ours, another provider's own way (a redirect to its completion
link) where it published the HIT, nothing (the page's old externalSubmit) for a HIT that is not
in our records."""

from __future__ import annotations

from typing import Any
from urllib.parse import parse_qs, urlsplit

import httpx
import pytest

from backend.crowd.provider import Completion
from tests.backend.market.helpers import accept, external_question

PROLIFIC_DONE = "https://app.prolific.com/submissions/complete?cc=C1A2B3C4"


def _task_token(mturk: Any, hit_id: str) -> str:
    question = mturk.get_hit(HITId=hit_id)["HIT"]["Question"]
    url = question.split("<ExternalURL>")[1].split("</ExternalURL>")[0].replace("&amp;", "&")
    return parse_qs(urlsplit(url).query)["task"][0]


def _start(base: str, mturk: Any, hit_id: str, worker_id: str) -> tuple[httpx.Response, str]:
    """The worker accepts the HIT and its page starts the assignment: (reply, AssignmentId)."""
    market_id = accept(hit_id, worker_id)
    return httpx.post(f"{base}/api/annotate/start", timeout=30, json={
        "task_token": _task_token(mturk, hit_id), "assignment_id": market_id,
        "worker_id": worker_id, "hit_id": hit_id}), market_id


def test_our_mturk_hit_completes_by_the_externalsubmit_form(
    crowd_url: str, mturk: Any, hit_ids: list[str]
) -> None:
    reply, _ = _start(crowd_url, mturk, hit_ids[0], "AWORKERCOMPLETE1")
    assert reply.status_code == 200, reply.text
    done = reply.json()["completion"]
    # The form's address: the marketplace's externalSubmit, or "" for the page's turkSubmitTo.
    assert done["kind"] == "form_post"
    assert done["url"] in ("", f"{crowd_url}/mturk/externalSubmit")
    assert reply.json()["token"]


def test_the_hits_provider_decides_the_completion(
    crowd_url: str, mturk: Any, hit_ids: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A provider that completes by redirect (Prolific's way) is asked with the HIT's and the
    assignment's ids, and its link reaches the page unchanged."""
    from backend.crowd import completion

    asked: list[tuple[str | None, str, str]] = []

    class Redirecting:
        def __init__(self, name: str | None) -> None:
            self.name = name

        def completion(self, unit_id: str, assignment_id: str) -> Completion:
            asked.append((self.name, unit_id, assignment_id))
            return Completion("redirect", PROLIFIC_DONE)

    monkeypatch.setattr(completion, "get_provider", Redirecting)
    reply, market_id = _start(crowd_url, mturk, hit_ids[1], "AWORKERCOMPLETE2")
    assert reply.status_code == 200, reply.text
    assert reply.json()["completion"] == {"kind": "redirect", "url": PROLIFIC_DONE}
    assert asked == [("mturk", hit_ids[1], market_id)]


def test_a_hit_not_in_our_records_has_no_completion(
    crowd_url: str, mturk: Any, tasks: list[int]
) -> None:
    """A HIT made straight on the marketplace for one of our task pages (not through publish)
    leaves the page to its externalSubmit form, as before."""
    from backend.annotation.service import get_task_or_raise
    from backend.annotation.tokens import task_token
    from backend.db import session_scope

    with session_scope() as session:
        token = task_token(get_task_or_raise(session, tasks[0]))
    hit = mturk.create_hit(
        Title="Straight on the marketplace", Description="d", Reward="0.10", MaxAssignments=1,
        LifetimeInSeconds=3600, AssignmentDurationInSeconds=600,
        Question=external_question(f"{crowd_url}/annotate/?task={token}"))["HIT"]
    reply, _ = _start(crowd_url, mturk, hit["HITId"], "AWORKERCOMPLETE3")
    assert reply.status_code == 200, reply.text
    assert reply.json()["completion"] is None
