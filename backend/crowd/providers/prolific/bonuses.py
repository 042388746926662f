"""Bonuses on Prolific: set up a bulk bonus payment, then pay it, once.

Prolific's pay call is not idempotent (sent twice, it pays twice), and payments compete for
the workspace's wallet: concurrent ones answer 429. So:

- the bonus's row (``prolific_bonuses``, by our key) is written before any call, the bulk
  payment's id as soon as Prolific set it up, and "paying" just before the pay call;
- a bonus found "paying" (a run whose reply was lost) is looked up on Prolific (the bulk
  payment's status) before it is paid again: paid there, it is only marked paid here;
- one bonus is paid at a time in the whole deployment: a lock in the process and the
  "wallet" lease in the database (``prolific_leases``; one conditional UPDATE takes it, on
  SQLite and PostgreSQL alike, and no transaction is held open across the calls);
- a 429 is backed off and tried again by the client (exponential, jittered, bounded).
"""

from __future__ import annotations

import os
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import timedelta
from typing import Any, cast

from sqlalchemy import CursorResult, or_, select, update
from sqlalchemy.dialects.postgresql import insert as pg_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert

from backend.crowd.provider import BonusOrder, ProviderError, ProviderRefused
from backend.crowd.providers.prolific.client import ProlificClient
from backend.crowd.providers.prolific.models import ProlificBonus, ProlificLease
from backend.db import session_scope, utcnow

WALLET = "wallet"
# Longer than one bonus takes with every retry; a holder that died frees the wallet after it.
LEASE_S = 120.0
LEASE_WAIT_S = 300.0
PAID_STATUSES = ("PAID", "COMPLETED", "PROCESSED")

_process_wallet = threading.Lock()


@contextmanager
def wallet() -> Iterator[None]:
    """Hold the workspace wallet: this process's lock, then the database lease."""
    with _process_wallet:
        holder = f"{os.getpid()}:{uuid.uuid4().hex[:12]}"
        _take_lease(holder)
        try:
            yield
        finally:
            with session_scope() as session:
                session.execute(update(ProlificLease)
                                .where(ProlificLease.name == WALLET,
                                       ProlificLease.holder == holder)
                                .values(holder=None, until=None))


def _take_lease(holder: str) -> None:
    deadline = time.monotonic() + LEASE_WAIT_S
    pause = 0.01
    while True:
        with session_scope() as session:
            insert = pg_insert if session.get_bind().dialect.name == "postgresql" \
                else sqlite_insert
            session.execute(insert(ProlificLease).values(name=WALLET, holder=None, until=None)
                            .on_conflict_do_nothing(index_elements=["name"]))
            now = utcnow()
            taken = cast(CursorResult[Any], session.execute(
                update(ProlificLease)
                .where(ProlificLease.name == WALLET,
                       or_(ProlificLease.holder.is_(None), ProlificLease.until < now))
                .values(holder=holder, until=now + timedelta(seconds=LEASE_S))
                .execution_options(synchronize_session=False))).rowcount
        if taken:
            return
        if time.monotonic() > deadline:
            raise ProviderError("another process has been paying Prolific bonuses for "
                                f"{LEASE_WAIT_S:.0f} s; try again later", "pay_bonus",
                                "throttled")
        time.sleep(pause)
        pause = min(pause * 2, 0.5)


def bonus_paid(client: ProlificClient, order: BonusOrder) -> bool:
    """Whether this bonus shows as paid: by our row, or, for one whose pay call was sent
    but not answered, by the bulk payment's status on Prolific."""
    with session_scope() as session:
        row = session.scalar(select(ProlificBonus).where(ProlificBonus.key == order.key))
        if row is None:
            return False
        state, bulk_id = row.state, row.bulk_id
    if state == "paid":
        return True
    if state == "paying" and bulk_id is not None and _paid_upstream(client, bulk_id):
        _set(order.key, state="paid")
        return True
    return False


def pay_bonus(client: ProlificClient, order: BonusOrder, study_id: str) -> None:
    """Pay ``order`` once, one payment at a time across the deployment."""
    if order.amount_cents <= 0:
        raise ProviderRefused("a bonus must be more than 0", "pay_bonus",
                              fields=[{"field": "amount", "message": "must be more than 0"}])
    _record(order, study_id)
    with wallet():
        if bonus_paid(client, order):
            return
        with session_scope() as session:
            bulk_id = session.scalar(select(ProlificBonus.bulk_id)
                                     .where(ProlificBonus.key == order.key))
        if bulk_id is None:
            # Setting a bonus up pays nothing: one whose reply was lost is left unpaid.
            amount = f"{order.amount_cents / 100:.2f}"
            made = client.post("/api/v1/submissions/bonus-payments/", {
                "study_id": study_id, "csv_bonuses": f"{order.worker_id},{amount}"})
            bulk_id = str(made["id"])
            _set(order.key, bulk_id=bulk_id)
        _set(order.key, state="paying")
        client.post(f"/api/v1/bulk-bonus-payments/{bulk_id}/pay/")
        _set(order.key, state="paid")


def _paid_upstream(client: ProlificClient, bulk_id: str) -> bool:
    reply = client.get(f"/api/v1/bulk-bonus-payments/{bulk_id}/")
    return str(reply.get("status", "")).upper() in PAID_STATUSES


def _record(order: BonusOrder, study_id: str) -> None:
    with session_scope() as session:
        insert = pg_insert if session.get_bind().dialect.name == "postgresql" else sqlite_insert
        session.execute(insert(ProlificBonus).values(
            key=order.key, study_id=study_id, submission_id=order.assignment_id,
            participant_id=order.worker_id, amount_cents=order.amount_cents, state="created",
            created_at=utcnow()).on_conflict_do_nothing(index_elements=["key"]))


def _set(key: str, **values: str) -> None:
    with session_scope() as session:
        session.execute(update(ProlificBonus).where(ProlificBonus.key == key).values(**values)
                        .execution_options(synchronize_session=False))
