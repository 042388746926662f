"""Sync, review actions, bonuses and costs against the built-in marketplace."""

from __future__ import annotations

from typing import Any

import pytest

from backend.config import get_settings
from backend.crowd import actions, costs, decisions, flows
from backend.crowd.client import make_client
from backend.crowd.publish import TooManyAssignments
from backend.crowd.sync import sync
from backend.db import session_scope
from backend.errors import Conflict
from backend.market import protocol
from tests.backend.crowd.helpers import synced_submission, worker_submits
from tests.backend.market.helpers import WORKER, WORKER_2

MTurk = Any


def _synced(crowd_url: str, hit_id: str, worker_id: str = WORKER) -> int:
    return synced_submission(crowd_url, hit_id, worker_id)


def test_sync_accepts_a_matching_submission_and_refuses_a_mismatched_worker(
    crowd_url: str, hit_ids: list[str],
) -> None:
    good, _ = worker_submits(crowd_url, hit_ids[0], WORKER)
    # Our page opened this assignment for another worker id than the marketplace's record.
    forged, forged_ours = worker_submits(crowd_url, hit_ids[1], WORKER_2,
                                         page_worker_id="A9IMPOSTOR")
    with session_scope() as session:
        result = sync(session, make_client(get_settings()))
    assert (result.hits, result.accepted, result.mismatched) == (5, 1, [forged])
    with session_scope() as session:
        again = sync(session, make_client(get_settings()))
        assert (again.accepted, again.already_accepted) == (0, 1)
        with pytest.raises(Conflict, match="sync"):
            decisions.approve(session, make_client(get_settings()), forged_ours)
    assert good not in result.unknown
    from typer.testing import CliRunner

    from backend.cli import app

    out = CliRunner().invoke(app, ["crowd", "sync"])
    assert out.exit_code == 0, out.output
    assert "0 new submissions accepted, 1 known, 1 refused" in out.output
    assert f"refused {forged}" in out.output


def test_approving_twice_is_a_clear_conflict(
    crowd_url: str, hit_ids: list[str], api: Any, mturk: MTurk,
) -> None:
    ours = _synced(crowd_url, hit_ids[0])
    first = api.post(f"/api/crowd/assignments/{ours}/approve", json={"feedback": "Thanks!"})
    assert first.status_code == 200, first.text
    assert (first.json()["amount"], first.json()["fee"]) == ("0.50", "0.10")
    second = api.post(f"/api/crowd/assignments/{ours}/approve", json={})
    assert second.status_code == 409
    assert second.json()["detail"] == f"assignment {ours} is already approved"
    rejected = api.post(f"/api/crowd/assignments/{ours}/reject", json={"feedback": "no"})
    assert rejected.status_code == 409 and "already approved" in rejected.json()["detail"]


def test_reject_without_feedback_is_422_and_with_it_rejects(
    crowd_url: str, hit_ids: list[str], api: Any, mturk: MTurk,
) -> None:
    ours = _synced(crowd_url, hit_ids[0])
    for body in ({}, {"feedback": ""}):
        resp = api.post(f"/api/crowd/assignments/{ours}/reject", json=body)
        assert resp.status_code == 422 and resp.json()["fields"][0]["field"] == "feedback"
    blank = api.post(f"/api/crowd/assignments/{ours}/reject", json={"feedback": "   "})
    assert blank.status_code == 422 and blank.json()["field"] == "feedback"
    resp = api.post(f"/api/crowd/assignments/{ours}/reject",
                    json={"feedback": "The joints were placed on the wrong hand."})
    assert resp.status_code == 200, resp.text
    with session_scope() as session:
        assert decisions._market_status(mturk, _assignment(session, ours)) == "Rejected"


def _assignment(session: Any, assignment_id: int) -> Any:
    from backend.annotation.service import get_assignment_or_raise

    return get_assignment_or_raise(session, assignment_id)


def _balance(mturk: MTurk) -> str:
    return str(mturk.get_account_balance()["AvailableBalance"])


def test_a_bonus_retried_after_service_faults_pays_once(
    crowd_url: str, hit_ids: list[str], mturk: MTurk,
) -> None:
    ours = _synced(crowd_url, hit_ids[0])
    with session_scope() as session:
        decisions.approve(session, mturk, ours)
    before = _balance(mturk)
    # Two faults before the marketplace commits, then one that loses the committed reply:
    # botocore retries all three, and the fourth attempt replays the token.
    protocol.inject_faults("SendBonus", 2)
    protocol.inject_faults("SendBonus", 1, after_commit=True)
    paid = flows.pay_bonus(mturk, ours, 100, "Careful work on occluded frames")
    assert not paid.already_done and (paid.amount, paid.fee) == ("1.00", "0.20")
    again = flows.pay_bonus(mturk, ours, 100, "Careful work on occluded frames")
    assert again.already_done
    with pytest.raises(Conflict, match="another key"):
        flows.pay_bonus(mturk, ours, 200, "Careful work on occluded frames")
    market_id = _market_id(ours)
    assert float(before) - float(_balance(mturk)) == pytest.approx(1.20)
    assert mturk.list_bonus_payments(AssignmentId=market_id)["NumResults"] == 1
    spend = _costs()
    assert spend.total.spent == "1.80"  # 0.50 + 0.10 fee, 1.00 + 0.20 fee
    assert [(w.key, w.spent) for w in spend.by_worker] == [(WORKER, "1.80")]
    assert spend.total.committed == "2.40"  # four open HITs at 0.60


def _market_id(assignment_id: int) -> str:
    with session_scope() as session:
        return _assignment(session, assignment_id).external_id


def _costs() -> Any:
    with session_scope() as session:
        return costs.costs(session)


def _act(action: Any, *args: Any) -> Any:
    """One action, one unit of work (as one admin request)."""
    with session_scope() as session:
        return action(session, *args)


def test_hit_and_worker_actions_are_recorded_once_with_clear_state_errors(
    crowd_url: str, hit_ids: list[str], mturk: MTurk,
) -> None:
    hit_id = hit_ids[0]
    _act(actions.add_assignments, mturk, hit_id, 2)
    with pytest.raises(TooManyAssignments):
        _act(actions.add_assignments, mturk, hit_id, 7)
    assert mturk.get_hit(HITId=hit_id)["HIT"]["MaxAssignments"] == 3
    _act(actions.expire_hit, mturk, hit_id)
    with pytest.raises(Conflict, match="already expired"):
        _act(actions.expire_hit, mturk, hit_id)
    _act(actions.extend_hit, mturk, hit_id, 3600)
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Assignable"
    type_id = _act(actions.grant_qualification, mturk, WORKER, None)
    holders = mturk.list_workers_with_qualification_type(QualificationTypeId=type_id)
    assert [q["WorkerId"] for q in holders["Qualifications"]] == [WORKER]
    with pytest.raises(Conflict, match="already holds"):
        _act(actions.grant_qualification, mturk, WORKER, None)
    _act(actions.revoke_qualification, mturk, WORKER, None)
    with pytest.raises(Conflict, match="does not hold"):
        _act(actions.revoke_qualification, mturk, WORKER, None)
    _act(actions.block_worker, mturk, WORKER_2, "Random clicks on every frame")
    with pytest.raises(Conflict, match="already blocked"):
        _act(actions.block_worker, mturk, WORKER_2, "again")
    # MTurk lets a requester message only workers whose work it approved or rejected.
    failures = actions.notify_workers(mturk, [WORKER], "New HITs", "Round 2 is open.")
    assert [(f["WorkerId"], f["NotifyWorkersFailureCode"]) for f in failures] == [
        (WORKER, "HardFailure")]


def _offered(worker_id: str) -> int:
    """How many HITs the marketplace offers the worker."""
    from backend.market import clock, workers

    with session_scope() as session:
        return len(workers.list_available_hits(session, worker_id, clock.now()))


def test_unblocking_lets_the_worker_back_and_unblocking_twice_is_a_conflict(
    hit_ids: list[str], api: Any,
) -> None:
    url = f"/api/crowd/workers/{WORKER_2}/block"
    assert api.post(url, json={"reason": "Random clicks on every frame"}).status_code == 200
    assert _offered(WORKER_2) == 0
    lifted = api.delete(url, params={"reason": "Appeal accepted"})
    assert lifted.status_code == 200, lifted.text
    assert lifted.json() == {"worker_id": WORKER_2, "state": "unblocked"}
    assert _offered(WORKER_2) == len(hit_ids)
    again = api.delete(url)
    assert again.status_code == 409
    assert again.json()["detail"] == f"worker {WORKER_2} is not blocked"
    never = api.delete(f"/api/crowd/workers/{WORKER}/block")
    assert never.status_code == 409 and "is not blocked" in never.json()["detail"]
    assert api.post(url, json={"reason": "Blocked again"}).status_code == 200
    assert _offered(WORKER_2) == 0
