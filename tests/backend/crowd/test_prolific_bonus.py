"""Prolific bonuses, on SQLite and PostgreSQL: each paid once, one at a time across threads
(the double records the most payments it saw at once), 429s backed off, and a bonus whose
reply was lost after the payment is not paid again."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Any

import pytest

from backend.crowd.provider import BonusOrder, ProviderUnreachable
from tests.backend.crowd.test_prolific_publish import units


@pytest.fixture
def prolific_db_url(database_url: str) -> str:
    """Both backends: the wallet lease is one conditional UPDATE on each."""
    return database_url


def order(unit_id: str, n: int, amount_cents: int = 25) -> BonusOrder:
    return BonusOrder(key=f"bonus-{n}", assignment_id=f"sub{n}", unit_id=unit_id,
                      worker_id=f"PID{n:03d}", amount_cents=amount_cents, reason="careful work")


def test_twenty_bonuses_at_once_are_paid_once_each_one_at_a_time(
        prolific: Any, prolific_provider: Any) -> None:
    (unit,) = prolific_provider.publish(units(1))
    prolific.faults["throttle_pays"] = 5
    orders = [order(unit.unit_id, n) for n in range(20)]

    with ThreadPoolExecutor(max_workers=20) as pool:
        list(pool.map(prolific_provider.pay_bonus, orders))

    assert sorted(who for _, who, _ in prolific.payments) == [f"PID{n:03d}" for n in range(20)]
    assert {amount for _, _, amount in prolific.payments} == {"0.25"}
    assert len({bulk for bulk, _, _ in prolific.payments}) == 20
    assert prolific.max_paying == 1
    assert prolific.counts["throttled_pays"] == 5  # each 429 backed off and tried again
    assert all(prolific_provider.bonus_paid(o) for o in orders)

    # Asked again: nothing more is paid.
    with ThreadPoolExecutor(max_workers=5) as pool:
        list(pool.map(prolific_provider.pay_bonus, orders[:5]))
    assert len(prolific.payments) == 20


def test_a_bonus_whose_reply_was_lost_after_payment_is_not_paid_again(
        prolific: Any, prolific_provider: Any) -> None:
    (unit,) = prolific_provider.publish(units(1))
    bonus = order(unit.unit_id, 1, amount_cents=120)
    assert prolific_provider.bonus_paid(bonus) is False
    prolific.faults["drop_after_pay"] = 1

    with pytest.raises(ProviderUnreachable):
        prolific_provider.pay_bonus(bonus)
    assert prolific.payments == [(prolific.payments[0][0], "PID001", "1.20")]

    assert prolific_provider.bonus_paid(bonus) is True
    prolific_provider.pay_bonus(bonus)
    assert len(prolific.payments) == 1
    pays = [path for method, path in prolific.requests if path.endswith("/pay/")]
    assert len(pays) == 1


def test_a_bonus_throttled_past_every_retry_is_paid_on_the_next_try_only_once(
        prolific: Any, prolific_provider: Any) -> None:
    (unit,) = prolific_provider.publish(units(1))
    bonus = order(unit.unit_id, 2)
    prolific.faults["throttle_pays"] = 50
    with pytest.raises(Exception, match="429"):
        prolific_provider.pay_bonus(bonus)
    assert prolific.payments == []
    assert prolific_provider.bonus_paid(bonus) is False
    prolific.faults["throttle_pays"] = 0
    prolific_provider.pay_bonus(bonus)
    prolific_provider.pay_bonus(bonus)
    assert [who for _, who, _ in prolific.payments] == ["PID002"]


def test_a_bonus_waits_while_another_process_holds_the_wallet(
        prolific: Any, prolific_provider: Any) -> None:
    """The database lease alone (no lock of this process) keeps payments one at a time."""
    import threading
    import time
    from datetime import timedelta

    from backend.crowd.providers.prolific.models import ProlificLease
    from backend.db import session_scope, utcnow

    (unit,) = prolific_provider.publish(units(1))
    with session_scope() as session:
        session.merge(ProlificLease(name="wallet", holder="4242:another",
                                    until=utcnow() + timedelta(seconds=60)))
    payer = threading.Thread(target=prolific_provider.pay_bonus, args=(order(unit.unit_id, 3),))
    payer.start()
    time.sleep(0.5)
    assert prolific.payments == [] and payer.is_alive()

    with session_scope() as session:
        session.merge(ProlificLease(name="wallet", holder=None, until=None))
    payer.join(timeout=10)
    assert [who for _, who, _ in prolific.payments] == ["PID003"]


def test_a_lease_left_by_a_dead_holder_runs_out(prolific: Any, prolific_provider: Any) -> None:
    from datetime import timedelta

    from backend.crowd.providers.prolific.models import ProlificLease
    from backend.db import session_scope, utcnow

    (unit,) = prolific_provider.publish(units(1))
    with session_scope() as session:
        session.merge(ProlificLease(name="wallet", holder="4242:dead",
                                    until=utcnow() - timedelta(seconds=1)))
    prolific_provider.pay_bonus(order(unit.unit_id, 4))
    assert [who for _, who, _ in prolific.payments] == ["PID004"]
