"""A requester's whole round, and races, on SQLite and on PostgreSQL.

This module swaps the per-test SQLite copy for the parametrised ``database_url`` of
tests/conftest.py, so each test runs once per database backend.
"""

from __future__ import annotations

import re
import threading
from datetime import timedelta

import pytest

from tests.backend.market.helpers import (
    WORKER,
    WORKER_2,
    WORKER_3,
    MTurk,
    accept,
    create_hit,
    error_of,
    make_client,
    submit,
    work,
)


@pytest.fixture
def market_database_url(database_url: str) -> str:
    return database_url


def test_a_requesters_round_from_publish_to_payment(market_url: str, mturk: MTurk) -> None:
    from backend.market import clock

    hit = create_hit(mturk, MaxAssignments=3, UniqueRequestToken="seq-1-view-0-round-1",
                     AutoApprovalDelayInSeconds=3600, AssignmentDurationInSeconds=120)
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        create_hit(mturk, MaxAssignments=3, UniqueRequestToken="seq-1-view-0-round-1")
    assert hit["HITId"] in error_of(exc)[2]
    hit_id = hit["HITId"]
    approved = work(market_url, hit_id, WORKER, tracks="[]")
    rejected = work(market_url, hit_id, WORKER_2, tracks="[]")
    abandoned = accept(hit_id, WORKER_3)
    clock.advance(121)  # WORKER_3 ran out of time: the slot is free again
    assert mturk.get_hit(HITId=hit_id)["HIT"]["NumberOfAssignmentsAvailable"] == 1
    assert submit(market_url, abandoned, tracks="[]").status_code == 400
    auto = work(market_url, hit_id, "A4WORKERFOUR", tracks="[]")
    mturk.approve_assignment(AssignmentId=approved)
    mturk.reject_assignment(AssignmentId=rejected, RequesterFeedback="No joints marked")
    mturk.send_bonus(WorkerId=WORKER, AssignmentId=approved, BonusAmount="0.50",
                     Reason="Great tracks", UniqueRequestToken="bonus-1")
    clock.advance(timedelta(hours=1, seconds=1))  # the fourth worker is approved automatically
    statuses = {a["AssignmentId"]: a["AssignmentStatus"] for a in
                mturk.list_assignments_for_hit(HITId=hit_id)["Assignments"]}
    assert statuses == {approved: "Approved", rejected: "Rejected", auto: "Approved"}
    assert mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"] == "Reviewable"
    mturk.delete_hit(HITId=hit_id)
    balance = mturk.get_account_balance()
    # Two approved assignments at 0.60 each and a 0.50 bonus with its 0.10 fee.
    assert (balance["AvailableBalance"], balance["OnHoldBalance"]) == ("9998.20", "0.00")


def test_racing_workers_get_the_last_slot_once(mturk: MTurk) -> None:
    hit_id = create_hit(mturk)["HITId"]
    outcomes: list[str] = []

    def take(worker_id: str) -> None:
        try:
            outcomes.append(accept(hit_id, worker_id))
        except Exception as exc:  # a lost race may surface as a lock error
            outcomes.append(type(exc).__name__)

    threads = [threading.Thread(target=take, args=(f"A{i}RACER",)) for i in range(6)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    winners = [o for o in outcomes if re.fullmatch(r"[A-Z0-9]{30}", o)]
    assert len(winners) == 1, outcomes
    assert mturk.get_hit(HITId=hit_id)["HIT"]["NumberOfAssignmentsPending"] == 1


def test_concurrent_retries_of_one_create_hit_make_one_hit(market_url: str) -> None:
    client = make_client(market_url, retries=4)
    results: list[str] = []

    def publish() -> None:
        try:
            results.append(create_hit(client, UniqueRequestToken="same-token")["HITId"])
        except client.exceptions.RequestError as exc:
            message = exc.response["Error"]["Message"]
            found = re.search(r"HITId ([A-Z0-9]+)", message)
            results.append(found.group(1) if found else message)

    threads = [threading.Thread(target=publish) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(set(results)) == 1 and len(results) == 4, results
    assert client.list_hits()["NumResults"] == 1


def test_concurrent_bonuses_never_overdraw_the_balance(market_url: str) -> None:
    from tests.backend.market.helpers import POOR_REQUESTER

    poor = make_client(market_url, key=POOR_REQUESTER, retries=4)
    assignment_id = work(market_url, create_hit(poor, Reward="0.01")["HITId"])
    outcomes: list[str] = []

    def bonus(index: int) -> None:
        try:
            poor.send_bonus(WorkerId=WORKER, AssignmentId=assignment_id, BonusAmount="0.30",
                            Reason=f"bonus {index}", UniqueRequestToken=f"race-{index}")
            outcomes.append("paid")
        except poor.exceptions.RequestError as exc:
            outcomes.append(exc.response.get("TurkErrorCode", ""))

    threads = [threading.Thread(target=bonus, args=(i,)) for i in range(5)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    # 1.00 - 0.02 (hold of a one-cent HIT and its minimum fee) leaves room for two 0.36
    # bonuses.
    assert sorted(outcomes) == ["AWS.MechanicalTurk.InsufficientFunds"] * 3 + ["paid"] * 2
    assert poor.get_account_balance()["AvailableBalance"] == "0.26"
