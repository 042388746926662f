"""A bonus is paid once, whatever happened to the run that started it, even after the
marketplace forgot its UniqueRequestToken (24 h): the ledger row is committed first."""

from __future__ import annotations

from datetime import timedelta
from typing import Any

import pytest
from sqlalchemy import select

from backend.annotation.service import get_assignment_or_raise
from backend.config import get_settings
from backend.crowd import decisions, flows
from backend.crowd.client import MarketplaceError, make_client
from backend.crowd.models import CrowdPayment
from backend.db import session_scope
from backend.market import clock, protocol
from tests.backend.crowd.helpers import synced_submission
from tests.backend.market.helpers import WORKER

REASON = "Careful work on occluded frames"


def _ledger(assignment_id: int) -> list[tuple[str, int, str]]:
    """(kind, amount in cents, state) of the assignment's bonus rows."""
    with session_scope() as session:
        rows = session.scalars(select(CrowdPayment).where(
            CrowdPayment.assignment_id == assignment_id, CrowdPayment.kind == "bonus")
            .order_by(CrowdPayment.id))
        return [(r.kind, r.amount_cents, r.state) for r in rows]


def _market_bonuses(mturk: Any, assignment_id: int) -> list[tuple[str, str]]:
    with session_scope() as session:
        market_id = get_assignment_or_raise(session, assignment_id).external_id
    payments = mturk.list_bonus_payments(AssignmentId=market_id)["BonusPayments"]
    return [(p["BonusAmount"], p["Reason"]) for p in payments]


def _balance(mturk: Any) -> float:
    return float(mturk.get_account_balance()["AvailableBalance"])


@pytest.fixture
def approved(crowd_url: str, hit_ids: list[str], mturk: Any) -> int:
    """An approved assignment of WORKER; our id."""
    ours = synced_submission(crowd_url, hit_ids[0], WORKER)
    with session_scope() as session:
        decisions.approve(session, mturk, ours)
    return ours


def test_a_lost_final_commit_rerun_after_a_day_pays_once(approved: int, mturk: Any) -> None:
    before = _balance(mturk)
    # The first run: its pending row is committed and SendBonus succeeds, then the process
    # dies before its last commit (the row stays pending).
    with session_scope() as session:
        intent = decisions.begin_bonus(session, approved, 100, REASON)
    decisions.send_bonus(mturk, intent)
    assert _ledger(approved) == [("bonus", 100, "pending")]
    clock.advance(timedelta(hours=25))  # the marketplace no longer knows the token
    paid = flows.pay_bonus(mturk, approved, 100, REASON)
    assert (paid.amount, paid.fee) == ("1.00", "0.20")
    assert _market_bonuses(mturk, approved) == [("1.00", REASON)]
    assert _ledger(approved) == [("bonus", 100, "done")]
    assert before - _balance(mturk) == pytest.approx(1.20)
    assert flows.pay_bonus(mturk, approved, 100, REASON).already_done
    assert len(_market_bonuses(mturk, approved)) == 1


def test_a_rerun_with_reworded_reason_finds_the_bonus_it_started(
    approved: int, mturk: Any,
) -> None:
    with session_scope() as session:
        intent = decisions.begin_bonus(session, approved, 100, REASON)
    decisions.send_bonus(mturk, intent)  # paid; the run dies before its last commit
    clock.advance(timedelta(hours=25))
    flows.pay_bonus(mturk, approved, 100, "Thanks for the careful work")
    assert _market_bonuses(mturk, approved) == [("1.00", REASON)]
    assert _ledger(approved) == [("bonus", 100, "done")]


def test_a_lost_reply_without_retries_leaves_it_pending_and_a_late_rerun_pays_once(
    approved: int, mturk: Any,
) -> None:
    impatient = make_client(get_settings(), attempts=1)
    protocol.inject_faults("SendBonus", 1, after_commit=True)  # paid, but the reply is lost
    with pytest.raises(MarketplaceError):
        flows.pay_bonus(impatient, approved, 100, REASON)
    assert _ledger(approved) == [("bonus", 100, "pending")]
    clock.advance(timedelta(hours=25))
    flows.pay_bonus(mturk, approved, 100, REASON)
    assert _market_bonuses(mturk, approved) == [("1.00", REASON)]
    assert _ledger(approved) == [("bonus", 100, "done")]


def test_a_run_that_died_before_paying_is_paid_by_the_rerun(approved: int, mturk: Any) -> None:
    with session_scope() as session:
        decisions.begin_bonus(session, approved, 100, REASON)  # committed, never sent
    clock.advance(timedelta(hours=25))
    flows.pay_bonus(mturk, approved, 100, REASON)
    assert _market_bonuses(mturk, approved) == [("1.00", REASON)]
    assert _ledger(approved) == [("bonus", 100, "done")]


def test_an_identical_bonus_under_another_key_is_not_mistaken_for_a_pending_one(
    approved: int, mturk: Any,
) -> None:
    flows.pay_bonus(mturk, approved, 100, REASON, key="week-1")
    with session_scope() as session:
        decisions.begin_bonus(session, approved, 100, REASON, key="week-2")  # died before paying
    flows.pay_bonus(mturk, approved, 100, REASON, key="week-2")
    assert _market_bonuses(mturk, approved) == [("1.00", REASON)] * 2
    assert _ledger(approved) == [("bonus", 100, "done")] * 2


def test_the_bonus_endpoint_pays_once_and_then_reports_it_done(
    approved: int, api: Any, mturk: Any,
) -> None:
    body = {"amount": "0.75", "reason": REASON, "key": "extra"}
    first = api.post(f"/api/crowd/assignments/{approved}/bonus", json=body)
    assert first.status_code == 200, first.text
    assert (first.json()["amount"], first.json()["fee"], first.json()["already_done"]) == (
        "0.75", "0.15", False)
    second = api.post(f"/api/crowd/assignments/{approved}/bonus", json=body)
    assert second.status_code == 200 and second.json()["already_done"] is True
    other = api.post(f"/api/crowd/assignments/{approved}/bonus", json={**body, "amount": "2"})
    assert other.status_code == 409 and "use another key" in other.json()["detail"]
    assert _market_bonuses(mturk, approved) == [("0.75", REASON)]


def test_the_cli_bonus_pays_once_and_says_so_on_a_rerun(approved: int, mturk: Any) -> None:
    from typer.testing import CliRunner

    from backend.cli import app

    args = ["crowd", "bonus", str(approved), "0.40", "--reason", REASON, "--key", "cli"]
    first = CliRunner().invoke(app, args)
    assert first.exit_code == 0, first.output
    assert f"bonus 'cli' of assignment {approved} paid: $0.40 (+ $0.08 fee) to {WORKER}" \
        in first.output
    again = CliRunner().invoke(app, args)
    assert again.exit_code == 0 and "already paid" in again.output
    assert _market_bonuses(mturk, approved) == [("0.40", REASON)]
    bad = CliRunner().invoke(app, ["crowd", "bonus", str(approved), "0.405", "--reason", REASON])
    assert bad.exit_code == 2 and "whole cents" in bad.output
