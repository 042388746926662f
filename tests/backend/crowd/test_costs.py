"""Costs after an approval, a bonus (paid and pending), a rejection, a waiting submission and
an expired HIT: rewards, bonuses and fees apart, for the project, per sequence and per worker."""

from __future__ import annotations

from typing import Any

import pytest
from sqlalchemy import select
from typer.testing import CliRunner

from backend.crowd import actions, costs, decisions, flows
from backend.crowd.schemas import CostLine, PublishOptions
from backend.db import session_scope
from tests.backend.crowd.helpers import make_tasks, synced_submission
from tests.backend.market.helpers import WORKER, WORKER_2, WORKER_3

# spent: rewards, bonuses, fees, total; committed: rewards, bonuses, fees, total
PROJECT = ("0.50", "1.00", "0.30", "1.80", "1.00", "0.50", "0.30", "1.80")


def _split(line: CostLine) -> tuple[str, ...]:
    return (line.spent_rewards, line.spent_bonuses, line.spent_fees, line.spent,
            line.committed_rewards, line.committed_bonuses, line.committed_fees, line.committed)


def _sequence_of(task_id: int) -> int:
    from backend.annotation.models import Task

    with session_scope() as session:
        return int(session.scalar(select(Task.sequence_id).where(Task.id == task_id)))


@pytest.fixture
def reviewed(crowd_url: str, mturk: Any) -> tuple[int, int]:
    """Sequence A (3 HITs): approved + $1.00 bonus paid + $0.50 bonus pending (WORKER),
    rejected (WORKER_2), one open. Sequence B (2 HITs): submitted, undecided (WORKER_3), and
    one expired with no work. Reward $0.50 + $0.10 fee each. Returns (A, B) sequence ids."""
    first, second = make_tasks(3, "grasp"), make_tasks(2, "pour")
    hits = flows.publish_each(mturk, PublishOptions(min_approval_rate=None), None).hit_ids
    approved = synced_submission(crowd_url, hits[0], WORKER)
    rejected = synced_submission(crowd_url, hits[1], WORKER_2)
    synced_submission(crowd_url, hits[3], WORKER_3)
    with session_scope() as session:
        decisions.approve(session, mturk, approved)
    with session_scope() as session:
        decisions.reject(session, mturk, rejected, "The joints were placed on the other hand.")
    flows.pay_bonus(mturk, approved, 100, "Careful work on occluded frames")
    with session_scope() as session:  # a bonus whose run stopped before paying
        decisions.begin_bonus(session, approved, 50, "Extra frames", key="extra")
    with session_scope() as session:
        actions.expire_hit(session, mturk, hits[4])
    return _sequence_of(first[0]), _sequence_of(second[0])


def test_costs_split_rewards_bonuses_and_fees_per_project_sequence_and_worker(
    reviewed: tuple[int, int],
) -> None:
    seq_a, seq_b = reviewed
    with session_scope() as session:
        report = costs.costs(session)
    assert _split(report.total) == PROJECT
    assert [(line.key, _split(line)) for line in report.by_sequence] == [
        (str(seq_a), ("0.50", "1.00", "0.30", "1.80", "0.50", "0.50", "0.20", "1.20")),
        (str(seq_b), ("0.00", "0.00", "0.00", "0.00", "0.50", "0.00", "0.10", "0.60"))]
    assert [(line.key, _split(line)) for line in report.by_worker] == [
        (WORKER, ("0.50", "1.00", "0.30", "1.80", "0.00", "0.50", "0.10", "0.60")),
        (WORKER_2, ("0.00",) * 8),
        (WORKER_3, ("0.00", "0.00", "0.00", "0.00", "0.50", "0.00", "0.10", "0.60"))]


def test_costs_endpoint_and_cli_report_the_same_numbers(
    reviewed: tuple[int, int], api: Any,
) -> None:
    from backend.cli import app

    resp = api.get("/api/crowd/costs")
    assert resp.status_code == 200, resp.text
    assert _split(CostLine.model_validate(resp.json()["total"])) == PROJECT
    out = CliRunner().invoke(app, ["crowd", "costs"])
    assert out.exit_code == 0, out.output
    rows = {line.split()[0] + (" " + line.split()[1] if line.startswith(("sequence", "worker"))
                               else ""): tuple(line.split()[-8:])
            for line in out.output.splitlines()[2:]}
    assert rows["project"] == PROJECT
    assert rows[f"sequence {reviewed[1]}"][-1] == "0.60"
    # Each sequence is named (subject/name) after its id.
    named = [line.split()[2] for line in out.output.splitlines()
             if line.startswith(f"sequence {reviewed[1]} ")]
    assert len(named) == 1 and "/" in named[0], out.output
    assert rows[f"worker {WORKER_3}"] == ("0.00", "0.00", "0.00", "0.00",
                                          "0.50", "0.00", "0.10", "0.60")
