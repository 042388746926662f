"""Money: holds on publishing, payment on approval, bonuses once per token, insufficient funds."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest

from backend.market.money import assignment_cost, assignment_fee, bonus_cost, parse_amount
from tests.backend.market.helpers import (
    POOR_REQUESTER,
    WORKER,
    WORKER_2,
    MTurk,
    accept,
    create_hit,
    error_of,
    make_client,
    work,
)


@pytest.mark.parametrize(("reward", "assignments", "fee"), [
    (50, 1, 10),      # 20%
    (100, 9, 20),
    (100, 10, 40),    # 10 or more assignments: 20% more
    (1, 1, 1),        # at least a cent per assignment
    (0, 1, 1),
    (3, 1, 1),        # 0.6 cents rounds half up to 1
    (13, 1, 3),       # 2.6 cents -> 3
    (2, 1, 1),        # 0.4 cents, but never below a cent
    (38, 12, 15),     # 15.2 cents -> 15
])
def test_fees_follow_mturk_pricing(reward: int, assignments: int, fee: int) -> None:
    assert assignment_fee(reward, assignments) == fee
    assert assignment_cost(reward, assignments) == reward + fee


def test_bonus_fee_is_a_fifth_with_a_one_cent_minimum() -> None:
    assert bonus_cost(125) == 150 and bonus_cost(1) == 2 and bonus_cost(3) == 4


@pytest.mark.parametrize(("text", "cents"), [("5", 500), ("5.", 500), ("5.5", 550),
                                             ("0.05", 5), ("101.42", 10142)])
def test_amounts_parse_like_mturk_writes_them(text: str, cents: int) -> None:
    assert parse_amount(text, "Reward") == cents


def _balance(client: MTurk) -> tuple[str, str]:
    balance = client.get_account_balance()
    return balance["AvailableBalance"], balance["OnHoldBalance"]


def test_publishing_holds_funds_that_approval_pays_and_rejection_returns(
    market_url: str, mturk: MTurk
) -> None:
    hit_id = create_hit(mturk, MaxAssignments=3)["HITId"]
    assert _balance(mturk) == ("9998.20", "1.80")
    first, second = work(market_url, hit_id), work(market_url, hit_id, WORKER_2)
    mturk.approve_assignment(AssignmentId=first)
    assert _balance(mturk) == ("9998.20", "1.20")
    mturk.reject_assignment(AssignmentId=second, RequesterFeedback="empty tracks")
    assert _balance(mturk) == ("9998.80", "0.60")
    mturk.update_expiration_for_hit(HITId=hit_id, ExpireAt=datetime(2015, 1, 1, tzinfo=UTC))
    assert _balance(mturk) == ("9999.40", "0.00")


def test_a_bonus_costs_its_fee_and_is_paid_once_per_token(market_url: str, mturk: MTurk) -> None:
    hit_id = create_hit(mturk)["HITId"]
    assignment_id = work(market_url, hit_id)
    mturk.approve_assignment(AssignmentId=assignment_id)
    first = mturk.send_bonus(WorkerId=WORKER, AssignmentId=assignment_id, BonusAmount="1.25",
                             Reason="Careful work on the occluded frames",
                             UniqueRequestToken="bonus-17-1")
    assert _balance(mturk) == ("9997.90", "0.00")  # 10000 - 0.60 - (1.25 + 0.25)
    with pytest.raises(mturk.exceptions.RequestError) as exc:
        mturk.send_bonus(WorkerId=WORKER, AssignmentId=assignment_id, BonusAmount="1.25",
                         Reason="Careful work on the occluded frames",
                         UniqueRequestToken="bonus-17-1")
    assert first["ResponseMetadata"]["RequestId"] in error_of(exc)[2]
    assert _balance(mturk) == ("9997.90", "0.00")
    payments = mturk.list_bonus_payments(AssignmentId=assignment_id)["BonusPayments"]
    assert [(p["WorkerId"], p["BonusAmount"]) for p in payments] == [(WORKER, "1.25")]


def test_a_bonus_retried_after_a_lost_reply_pays_once(market_url: str, mturk: MTurk) -> None:
    from backend.market.protocol import inject_faults

    assignment_id = work(market_url, create_hit(mturk)["HITId"])
    inject_faults("SendBonus", 1, after_commit=True)  # paid, but the reply is a ServiceFault
    patient = make_client(market_url, retries=3)
    with pytest.raises(patient.exceptions.RequestError, match="already been processed"):
        patient.send_bonus(WorkerId=WORKER, AssignmentId=assignment_id, BonusAmount="2",
                           Reason="thanks", UniqueRequestToken="bonus-retried")
    assert mturk.list_bonus_payments(AssignmentId=assignment_id)["NumResults"] == 1


def test_a_bonus_goes_only_to_the_assignments_worker(market_url: str, mturk: MTurk) -> None:
    hit_id = create_hit(mturk, MaxAssignments=2)["HITId"]
    assignment_id = work(market_url, hit_id)
    with pytest.raises(mturk.exceptions.RequestError, match="was not worked by"):
        mturk.send_bonus(WorkerId=WORKER_2, AssignmentId=assignment_id, BonusAmount="1",
                         Reason="thanks")
    in_progress = accept(hit_id, WORKER_2)
    with pytest.raises(mturk.exceptions.RequestError, match="does not exist"):
        mturk.send_bonus(WorkerId=WORKER_2, AssignmentId=in_progress, BonusAmount="1",
                         Reason="thanks")
    with pytest.raises(mturk.exceptions.RequestError, match=r"more than 0\.00"):
        mturk.send_bonus(WorkerId=WORKER, AssignmentId=assignment_id, BonusAmount="0",
                         Reason="thanks")


def test_list_bonus_payments_pages_by_hit(market_url: str, mturk: MTurk) -> None:
    hit_id = create_hit(mturk, MaxAssignments=2)["HITId"]
    done = [work(market_url, hit_id), work(market_url, hit_id, WORKER_2)]
    for index in range(5):
        assignment_id = done[index % 2]
        worker = WORKER if index % 2 == 0 else WORKER_2
        mturk.send_bonus(WorkerId=worker, AssignmentId=assignment_id, BonusAmount=f"0.{index}1",
                         Reason=f"bonus {index}")
    pages = list(mturk.get_paginator("list_bonus_payments").paginate(
        HITId=hit_id, PaginationConfig={"PageSize": 2}))
    assert [p["NumResults"] for p in pages] == [2, 2, 1]
    amounts = [b["BonusAmount"] for p in pages for b in p["BonusPayments"]]
    assert amounts == ["0.01", "0.11", "0.21", "0.31", "0.41"]
    with pytest.raises(mturk.exceptions.RequestError, match="HITId or an AssignmentId"):
        mturk.list_bonus_payments()


def test_spending_beyond_the_balance_is_refused(market_url: str) -> None:
    poor = make_client(market_url, key=POOR_REQUESTER)
    assert _balance(poor) == ("1.00", "0.00")
    with pytest.raises(poor.exceptions.RequestError) as exc:
        create_hit(poor, MaxAssignments=2)  # 2 x (0.50 + 0.10) = 1.20
    _, turk_code, message = error_of(exc)
    assert turk_code == "AWS.MechanicalTurk.InsufficientFunds" and "$1.20" in message
    assert poor.list_hits()["NumResults"] == 0 and _balance(poor) == ("1.00", "0.00")
    hit_id = create_hit(poor)["HITId"]
    with pytest.raises(poor.exceptions.RequestError, match="Insufficient funds"):
        poor.create_additional_assignments_for_hit(HITId=hit_id, NumberOfAdditionalAssignments=1)
    assignment_id = work(market_url, hit_id)
    poor.approve_assignment(AssignmentId=assignment_id)  # paid from the hold: always possible
    with pytest.raises(poor.exceptions.RequestError, match="Insufficient funds"):
        poor.send_bonus(WorkerId=WORKER, AssignmentId=assignment_id, BonusAmount="0.40",
                        Reason="thanks")
    assert _balance(poor) == ("0.40", "0.00")
