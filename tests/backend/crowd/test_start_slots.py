"""Starts of a HIT are bounded by its held slots: a task token (every previewer has one) opens
no more assignments of a HIT than workers hold on the marketplace; work opened longer ago than
the HIT's assignment duration has expired and frees its slot; and progress counts no more
marketplace work being done than the task's HITs offer."""

from __future__ import annotations

from datetime import timedelta
from typing import Any

from sqlalchemy import update

from backend.annotation.models import Assignment
from backend.db import session_scope, utcnow
from tests.backend.crowd.test_start import _start, _task_of, _task_token
from tests.backend.market.helpers import accept


def _working(task_id: int) -> int:
    from backend.progress.service import task_states

    with session_scope() as session:
        return task_states(session, [task_id])[task_id].assignments.working


def test_a_task_token_opens_no_more_assignments_than_workers_hold(
    crowd_url: str, mturk: Any, hit_ids: list[str],
) -> None:
    hit_id = hit_ids[0]
    token = _task_token(mturk, hit_id)
    genuine = accept(hit_id, "AWORKERGENUINE01")
    assert _start(crowd_url, token, genuine, "AWORKERGENUINE01", hit_id).status_code == 200
    forged = [_start(crowd_url, token, f"FORGED{i:04d}", f"AFORGER{i:04d}", hit_id)
              for i in range(20)]
    assert [r.status_code for r in forged] == [403] * 20, [r.text for r in forged]
    assert forged[0].json()["error"] == "forbidden"
    assert (f"HIT {hit_id} has 1 assignment(s) held by workers and 1 already opened here"
            in forged[0].json()["detail"])
    # The genuine worker's assignment opens again, as before.
    assert _start(crowd_url, token, genuine, "AWORKERGENUINE01", hit_id).status_code == 200
    assert _working(_task_of(hit_id)) == 1

    # Past the HIT's assignment duration the marketplace has taken the assignment back:
    # the work opened here has expired and its slot is open again.
    duration = mturk.get_hit(HITId=hit_id)["HIT"]["AssignmentDurationInSeconds"]
    with session_scope() as session:
        session.execute(update(Assignment).where(Assignment.external_id == genuine)
                        .values(created_at=utcnow() - timedelta(seconds=duration + 60)))
    late = _start(crowd_url, token, "FORGED9999", "AFORGER9999", hit_id)
    assert late.status_code == 200, late.text


def test_progress_counts_no_more_marketplace_work_than_the_hits_offer(
    crowd_url: str, mturk: Any, hit_ids: list[str],
) -> None:
    """Rows opened before starts were bounded (or by a lost race) count up to the slots."""
    hit_id = hit_ids[0]
    task_id = _task_of(hit_id)
    with session_scope() as session:
        for i in range(20):
            session.add(Assignment(task_id=task_id, worker_id=f"AFORGER{i:04d}", hit_id=hit_id,
                                   external_id=f"FORGED{i:04d}"))
        session.add(Assignment(task_id=task_id, worker_id="ADIRECT", external_id="DIRECT1"))
    # One HIT of one assignment, and one direct link.
    assert _working(task_id) == 2
