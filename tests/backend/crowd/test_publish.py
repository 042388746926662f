"""Publishing tasks as HITs through boto3 against the built-in marketplace."""

from __future__ import annotations

import re
from decimal import Decimal
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select
from typer.testing import CliRunner

from backend.config import get_settings
from backend.crowd import flows, pricing
from backend.crowd.client import make_client
from backend.crowd.models import CrowdHit
from backend.crowd.publish import EXTERNAL_QUESTION_NS, TooManyAssignments
from backend.crowd.schemas import PublishOptions
from backend.db import session_scope
from backend.market import protocol

OPEN = PublishOptions(min_approval_rate=None)


def _hits(client: Any) -> list[dict[str, Any]]:
    return [hit for page in client.get_paginator("list_hits").paginate() for hit in page["HITs"]]


def _publish(client: Any, options: PublishOptions = OPEN) -> flows.PublishResult:
    with session_scope() as session:
        return flows.publish(session, client, options, None)


def test_publish_creates_one_hit_per_task_pointing_at_the_annotation_page(
    crowd_url: str, tasks: list[int],
) -> None:
    client = make_client(get_settings())
    result = _publish(client, PublishOptions(locales=["US", "DE"], require_training=True))
    assert (result.created, result.recovered, len(set(result.hit_ids))) == (5, 0, 5)
    hits = _hits(client)
    assert sorted(h["HITId"] for h in hits) == sorted(result.hit_ids)
    for hit in hits:
        assert EXTERNAL_QUESTION_NS in hit["Question"]
        url = re.search(r"<ExternalURL>(.*)</ExternalURL>", hit["Question"]).group(1)
        assert url.startswith(f"{crowd_url}/annotate/?task=")
        assert "<FrameHeight>900</FrameHeight>" in hit["Question"]
        assert (hit["Reward"], hit["MaxAssignments"]) == ("0.50", 1)
        types = {r["QualificationTypeId"] for r in hit["QualificationRequirements"]}
        assert {"000000000000000000L0", "00000000000000000071"} < types and len(types) == 3
    again = _publish(client)
    assert (again.created, again.already_published) == (0, 0)  # nothing due any more
    assert len(_hits(client)) == 5


class KilledAfter:
    """The real client, killed right after the marketplace answered its ``n``-th CreateHIT."""

    def __init__(self, client: Any, n: int) -> None:
        self._client, self._left = client, n

    def __getattr__(self, name: str) -> Any:
        return getattr(self._client, name)

    def create_hit(self, **params: Any) -> dict[str, Any]:
        reply = self._client.create_hit(**params)
        self._left -= 1
        if self._left == 0:
            raise KeyboardInterrupt("killed")
        return reply


@pytest.mark.parametrize("per_task_commit", [True, False])
def test_a_publish_killed_midway_and_rerun_yields_exactly_one_hit_per_task(
    crowd_url: str, tasks: list[int], per_task_commit: bool,
) -> None:
    client = make_client(get_settings())
    killed = KilledAfter(client, 3)
    with pytest.raises(KeyboardInterrupt):
        flows.publish_each(killed, OPEN, None) if per_task_commit else _publish(killed)
    assert len(_hits(client)) == 3
    result = flows.publish_each(client, OPEN, None) if per_task_commit else _publish(client)
    # The third HIT was created but its row lost with the crash: recovered, not duplicated.
    assert (result.created, result.recovered) == ((2, 1) if per_task_commit else (2, 3))
    hits = _hits(client)
    assert len(hits) == len(tasks) == len({h["HITId"] for h in hits})
    with session_scope() as session:
        recorded = session.execute(select(CrowdHit.task_id, CrowdHit.hit_id)).all()
    assert sorted(task_id for task_id, _ in recorded) == sorted(tasks)
    assert sorted(hit_id for _, hit_id in recorded) == sorted(h["HITId"] for h in hits)


def test_a_create_hit_reply_lost_after_commit_is_recovered_by_botocores_retry(
    crowd_url: str, tasks: list[int],
) -> None:
    protocol.inject_faults("CreateHIT", 1, after_commit=True)
    client = make_client(get_settings())
    result = _publish(client)
    assert (result.created, result.recovered) == (4, 1)
    assert len(_hits(client)) == 5


def test_dry_run_prices_rewards_fees_the_ten_assignment_rule_and_the_cent_minimum(
    crowd_url: str, tasks: list[int],
) -> None:
    with session_scope() as session:
        base = flows.plan(session, PublishOptions(), None).cost
        large = flows.plan(session, PublishOptions(max_assignments=10, allow_large_hits=True),
                           None).cost
        cheap = flows.plan(session, PublishOptions(reward=Decimal("0.02")), None).cost
    assert (base.hits, base.fee_per_assignment, base.total) == (5, "0.10", "3.00")
    assert (large.fee_per_assignment, large.rewards, large.fees, large.total) == (
        "0.20", "25.00", "10.00", "35.00")
    assert (cheap.fee_per_assignment, cheap.total) == ("0.01", "0.15")
    assert pricing.fee_cents(0) == 1 and pricing.fee_cents(3, 9) == 1
    assert pricing.fee_cents(3, 10) == 1
    assert pricing.fee_cents(250, 9) == 50 and pricing.fee_cents(250, 10) == 100


def test_cli_dry_run_prints_hit_count_and_cost_and_publishes_nothing(
    crowd_url: str, tasks: list[int],
) -> None:
    from backend.cli import app

    runner = CliRunner()
    out = runner.invoke(app, ["publish", "--dry-run", "--reward", "0.50", "--assignments", "2"])
    assert out.exit_code == 0, out.output
    assert "5 HITs x 2 assignment(s)" in out.output and "= $6.00" in out.output
    refused = runner.invoke(app, ["publish", "--dry-run", "--assignments", "10"])
    assert refused.exit_code == 2 and "20% more" in refused.output
    assert _hits(make_client(get_settings())) == []


def test_ten_or_more_assignments_are_refused_without_the_explicit_flag(
    crowd_url: str, tasks: list[int],
) -> None:
    with session_scope() as session, pytest.raises(TooManyAssignments):
        flows.publish(session, make_client(get_settings()),
                      PublishOptions(max_assignments=10), None)
    assert _hits(make_client(get_settings())) == []


def test_publish_endpoint_needs_an_admin_and_names_the_assignment_rule(
    crowd_url: str, tasks: list[int],
) -> None:
    from backend.app import create_app
    from tests.backend.crowd.helpers import admin_headers

    with TestClient(create_app()) as api:
        assert api.post("/api/crowd/publish", json={}).status_code == 401
        headers = admin_headers(api)
        resp = api.post("/api/crowd/publish", json={"max_assignments": 12}, headers=headers)
        assert resp.status_code == 422 and resp.json()["field"] == "max_assignments"
        resp = api.post("/api/crowd/publish", json={"min_approval_rate": None}, headers=headers)
        assert resp.status_code == 200, resp.text
        assert resp.json()["created"] == 5 and resp.json()["cost"]["total"] == "3.00"


def test_a_new_task_given_a_deleted_tasks_id_gets_its_own_hit(
    crowd_url: str, tasks: list[int],
) -> None:
    """SQLite hands a deleted task's id to the next task made; publishing that new task must
    create its own HIT, not recover the deleted task's (expired) one from the marketplace."""
    from datetime import timedelta

    from sqlalchemy import delete

    from backend.annotation.models import Task

    client = make_client(get_settings())
    first = _publish(client)
    assert first.created == len(tasks)
    # What deleting the sequence and importing another leaves: the same ids, new tasks.
    with session_scope() as session:
        session.execute(delete(CrowdHit))
        for task in session.scalars(select(Task)):
            task.created_at = task.created_at + timedelta(seconds=1)
    again = _publish(client)
    assert (again.created, again.recovered) == (len(tasks), 0)
    assert not set(again.hit_ids) & set(first.hit_ids)
    # The same task published again is still found, never duplicated.
    with session_scope() as session:
        session.execute(delete(CrowdHit))
    rerun = _publish(client)
    assert (rerun.created, rerun.recovered) == (0, len(tasks))
    assert sorted(rerun.hit_ids) == sorted(again.hit_ids)
