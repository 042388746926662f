"""The crowd's loop on each provider, over HTTP against the app served on loopback: publish the
hand tasks with that provider, a worker takes a unit the provider's way, the annotation page
starts the assignment with the ids its address carries and learns how to complete, saves and
submits tracks, crowd sync (Prolific: its webhook) records the submission, the QC job scores
it, an admin approves it, rejects a second unit's work and pays a bonus, and the costs show each
provider's amounts in its own fees and currency.

mturk and team run on the built-in marketplace (the mturk worker through the marketplace's
worker service, the team member through the portal); prolific against the Prolific test double.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import httpx
import numpy as np
import pytest
from sqlalchemy import select

from backend.db import session_scope
from tests.backend.crowd.conftest import WEBHOOK_SECRET
from tests.backend.crowd.helpers import admin_headers
from tests.backend.market.helpers import accept

__all__ = ["WEBHOOK_SECRET"]

REWARD = "0.50"
BONUS = "0.20"
PROLIFIC_REWARD = "1.50"  # over Prolific's hourly floor for a hand task's expected time
# Two views of six in: the careful work passes on its own evidence, the careless one waits
# for an admin (no consensus yet to reject it on), which is why the admin decides here.
QC_SEES = [("approve", True), ("review", True)]
REJECTION = ("The tracked joints sit far from the hand in most frames of this view, so the "
             "work cannot be used; please look at the examples before trying again.")


@dataclass
class Work:
    """One worker's take of one unit, as the page saw it."""

    unit_id: str
    ids: dict[str, str]  # what the page sends to /api/annotate/start
    completion: dict[str, str]
    assignment_id: int  # ours


class Loop:
    """The admin's side, over HTTP, and the annotation page's calls."""

    def __init__(self, base: str, capture: Path) -> None:
        from backend.captures.truth import CaptureTruth

        self.base = base
        self.http = httpx.Client(base_url=base, timeout=60)
        self.http.headers.update(admin_headers(self.http))
        self.truth = CaptureTruth(capture)
        self.rng = np.random.default_rng(3)

    def publish(self, provider: str, reward: str, **extra: Any) -> list[str]:
        """Publish every task with ``provider``; the units of the first two hand tasks."""
        from backend.annotation.models import Task
        from backend.crowd.models import CrowdHit

        reply = self.http.post("/api/crowd/publish", json={
            "provider": provider, "reward": reward, "min_approval_rate": None, **extra})
        assert reply.status_code == 200, reply.text
        assert reply.json()["cost"]["provider"] == provider
        with session_scope() as session:
            hands = list(session.scalars(
                select(CrowdHit.hit_id).join(Task, Task.id == CrowdHit.task_id)
                .where(Task.kind == "hand", CrowdHit.provider == provider)
                .order_by(Task.id)))
        assert set(hands) <= set(reply.json()["hit_ids"])
        return hands[:2]

    def page(self, unit_id: str, task_token: str, ids: dict[str, str], profile: str) -> Work:
        """The page: start with the address's ids, save half the tracks, submit them all."""
        from backend.crowd.simulate import annotate

        started = httpx.post(f"{self.base}/api/annotate/start", timeout=30,
                             json={"task_token": task_token, **ids})
        assert started.status_code == 200, started.text
        auth = {"Authorization": f"Bearer {started.json()['token']}"}
        task = httpx.get(f"{self.base}/api/annotate/task", headers=auth, timeout=30).json()
        xy, visible = self.truth.points(task["task"], self.rng)
        work = annotate(xy, visible, (task["task"]["width"], task["task"]["height"]), profile,
                        self.rng)
        body = [{"point": p, "keyframes": rows} for p, rows in enumerate(work.tracks)]
        version = task["assignment"]["version"]
        saved = httpx.put(f"{self.base}/api/annotate/tracks", headers=auth, timeout=30, json={
            "version": version, "tracks": body[:10], "edit_count": 10, "working_time_s": 60.0})
        assert saved.status_code == 200, saved.text
        done = httpx.post(f"{self.base}/api/annotate/submit", headers=auth, timeout=30, json={
            "version": saved.json()["version"], "tracks": body, "edit_count": 25,
            "working_time_s": 150.0})
        assert done.status_code == 200 and done.json()["status"] == "submitted", done.text
        return Work(unit_id, ids, started.json()["completion"], task["assignment"]["id"])

    def sync(self) -> int:
        reply = self.http.post("/api/crowd/sync")
        assert reply.status_code == 200, reply.text
        return int(reply.json()["accepted"])

    def decide(self, careful: Work, careless: Work, category: str | None = None) -> None:
        """Approve the careful work with a bonus, reject the careless work."""
        approved = self.http.post(f"/api/crowd/assignments/{careful.assignment_id}/approve",
                                  json={"feedback": "Clean joints, thank you."})
        assert approved.status_code == 200, approved.text
        rejected = self.http.post(f"/api/crowd/assignments/{careless.assignment_id}/reject",
                                  json={"feedback": REJECTION, "category": category})
        assert rejected.status_code == 200, rejected.text
        bonus = self.http.post(f"/api/crowd/assignments/{careful.assignment_id}/bonus",
                               json={"amount": BONUS, "reason": "careful work"})
        assert bonus.status_code == 200, bonus.text

    def costs(self, provider: str) -> dict[str, str]:
        reply = self.http.get("/api/crowd/costs")
        assert reply.status_code == 200, reply.text
        (line,) = [line for line in reply.json()["by_provider"] if line["key"] == provider]
        return {k: line[k] for k in ("currency", "spent_rewards", "spent_bonuses", "spent_fees",
                                     "spent")}


@pytest.fixture
def hands(crowd_url: str, qc_capture: Path) -> int:
    """The synthetic capture imported with its tasks; the sequence id."""
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.storage import get_storage

    sequence_id = import_path(qc_capture)[0].sequence_id
    with session_scope() as session:
        create_tasks(session, get_storage(), sequence_id)
    return sequence_id


@pytest.fixture
def loop(crowd_url: str, qc_capture: Path, hands: int) -> Iterator[Loop]:
    made = Loop(crowd_url, qc_capture)
    yield made
    made.http.close()


def task_token(page_url: str) -> str:
    return parse_qs(urlsplit(page_url).query)["task"][0]


def hit_page(unit_id: str) -> str:
    from backend.config import get_settings
    from backend.crowd.providers.mturk_client import make_client

    question = make_client(get_settings()).get_hit(HITId=unit_id)["HIT"]["Question"]
    return question.split("<ExternalURL>")[1].split("</ExternalURL>")[0].replace("&amp;", "&")


def confirmed(works: list[Work]) -> list[str]:
    """Run the confirm jobs the page's submits queued; their states."""
    from backend.jobs.models import Job
    from backend.jobs.runner import execute
    from backend.pipeline import confirm_key

    for work in works:
        execute(confirm_key(work.assignment_id))
    with session_scope() as session:
        return [str(session.scalar(select(Job.status).where(
            Job.key == confirm_key(work.assignment_id)))) for work in works]


def scored(sequence_id: int, works: list[Work]) -> list[Any]:
    """Run the target's QC job (queued by the sync or the confirm job); per work, its
    report's (outcome, provisional)."""
    from backend.jobs.runner import execute
    from backend.quality.models import QCReport
    from backend.quality.service import qc_key

    execute(qc_key(sequence_id, "hand:0"))
    ids = [work.assignment_id for work in works]
    with session_scope() as session:
        found = {r.assignment_id: (r.outcome, r.provisional) for r in
                 session.scalars(select(QCReport).where(QCReport.assignment_id.in_(ids)))}
    return [found.get(i) for i in ids]


def test_mturk_loop_completes_by_form_and_costs_usd_with_twenty_percent(
    loop: Loop, hands: int, crowd_url: str
) -> None:
    from tests.backend.market.helpers import submit

    units = loop.publish("mturk", REWARD, sequence_id=hands)
    works = []
    for unit_id, worker, profile in ((units[0], "AMTURKLOOP1", "careful"),
                                     (units[1], "AMTURKLOOP2", "spammer")):
        market_id = accept(unit_id, worker)  # the marketplace's worker service
        ids = {"assignment_id": market_id, "hit_id": unit_id, "worker_id": worker}
        work = loop.page(unit_id, task_token(hit_page(unit_id)), ids, profile)
        assert work.completion == {"kind": "form_post",
                                   "url": f"{crowd_url}/mturk/externalSubmit"}
        assert submit(crowd_url, market_id, result="submitted").status_code == 200
        works.append(work)
    assert loop.sync() == 2
    assert scored(hands, works) == QC_SEES
    loop.decide(*works)
    assert loop.costs("mturk") == {"currency": "USD", "spent_rewards": "0.50",
                                   "spent_bonuses": "0.20", "spent_fees": "0.14",
                                   "spent": "0.84"}


def portal_member(base: str, loop: Loop, name: str) -> tuple[str, dict[str, str]]:
    """A portal account the admin made, signed in; (worker id, auth header)."""
    email, password = f"{name}@lab.example.org", "team member password"
    made = loop.http.post("/api/portal/workers", json={"email": email, "password": password})
    assert made.status_code == 200, made.text
    login = httpx.post(f"{base}/api/portal/login", json={"email": email, "password": password})
    assert login.status_code == 200, login.text
    return made.json()["worker_id"], {"Authorization": f"Bearer {login.json()['access_token']}"}


def test_team_loop_completes_to_the_portal_and_costs_nothing_in_fees(
    loop: Loop, hands: int, crowd_url: str
) -> None:
    units = loop.publish("team", "0.00", sequence_id=hands)
    works = []
    for unit_id, name, profile in ((units[0], "amy", "careful"), (units[1], "ben", "spammer")):
        worker_id, auth = portal_member(crowd_url, loop, name)
        taken = httpx.post(f"{crowd_url}/api/portal/hits/{unit_id}/accept", headers=auth)
        assert taken.status_code == 200, taken.text
        query = {k: v[0] for k, v in parse_qs(urlsplit(taken.json()["work_url"]).query).items()}
        ids = {"assignment_id": query["assignmentId"], "hit_id": query["hitId"],
               "worker_id": query["workerId"]}
        assert (ids["hit_id"], ids["worker_id"]) == (unit_id, worker_id)
        work = loop.page(unit_id, query["task"], ids, profile)
        assert work.completion == {"kind": "portal", "url": f"{crowd_url}/market/#/hits"}
        # The page hands the assignment in (completion.js's handIn), then goes to the portal.
        handed = httpx.post(f"{query['turkSubmitTo']}/mturk/externalSubmit",
                            data={"assignmentId": ids["assignment_id"], "result": "submitted:2"})
        assert handed.status_code == 200, handed.text
        works.append(work)
    assert loop.sync() == 2
    assert scored(hands, works) == QC_SEES
    loop.decide(*works)
    assert loop.costs("team") == {"currency": "USD", "spent_rewards": "0.00",
                                  "spent_bonuses": "0.20", "spent_fees": "0.00",
                                  "spent": "0.20"}


def participant_page(external_url: str, participant: str, study_id: str,
                     submission: str) -> dict[str, str]:
    """The page's address as Prolific opens it (its placeholders filled in); the query."""
    url = (external_url.replace("{%PROLIFIC_PID%}", participant)
           .replace("{%STUDY_ID%}", study_id).replace("{%SESSION_ID%}", submission))
    return {k: v[0] for k, v in parse_qs(urlsplit(url).query).items()}


def test_prolific_loop_completes_by_redirect_with_its_code_and_costs_gbp_with_a_third(
    prolific: Any, loop: Loop, hands: int, crowd_url: str
) -> None:
    from backend.config import get_settings
    from backend.crowd.providers.prolific.webhooks import subscribe

    subscribe(get_settings(), f"{crowd_url}/api/crowd/prolific/webhook")
    units = loop.publish("prolific", PROLIFIC_REWARD, sequence_id=hands)
    (study,) = prolific.studies.values()
    works = []
    for unit_id, participant, profile in ((units[0], "PIDCAREFUL", "careful"),
                                          (units[1], "PIDCARELESS", "spammer")):
        position = int(unit_id.rpartition(":")[2])
        submission = prolific.take(study["id"], position, participant, status="ACTIVE")
        query = participant_page(study["access_details"][position]["external_url"],
                                 participant, study["id"], submission)
        # What the page sends (api.js readPageParams): Prolific's names for the ids.
        ids = {"assignment_id": query["SESSION_ID"], "hit_id": query["STUDY_ID"],
               "worker_id": query["PROLIFIC_PID"]}
        work = loop.page(unit_id, query["task"], ids, profile)
        code = study["completion_codes"][0]["code"]
        assert work.completion == {
            "kind": "redirect",
            "url": f"https://app.prolific.com/submissions/complete?cc={code}"}
        prolific.submissions[submission]["status"] = "AWAITING REVIEW"
        assert prolific.deliver("submission.status.change", submission,
                                "AWAITING REVIEW") == [200]
        works.append(work)
    assert loop.sync() == 0  # the webhook recorded both already
    # The page's submit queued each one's confirm job: it finds them recorded, queues the QC.
    assert confirmed(works) == ["done", "done"]
    assert scored(hands, works) == QC_SEES
    loop.decide(*works, category="LOW_EFFORT")
    assert [prolific.submissions[s]["status"] for s in prolific.submissions] == [
        "APPROVED", "REJECTED"]
    assert loop.costs("prolific") == {"currency": "GBP", "spent_rewards": "1.50",
                                      "spent_bonuses": "0.20", "spent_fees": "0.57",
                                      "spent": "2.27"}
