"""The cost report's running totals (crowd_cost_totals, crowd_hits.decided) stay exactly the
sums over the payment rows: after approvals, paid and pending bonuses, a rejection, a bonus
finished later, a forced sequence delete (whose money the workers' totals keep), and many
payments written at once on PostgreSQL."""

from __future__ import annotations

import threading
from typing import Any

import pytest
from sqlalchemy import func, select

from backend.crowd import decisions, totals
from backend.db import session_scope
from tests.backend.crowd.test_costs import reviewed

__all__ = ["reviewed"]

_Sums = dict[tuple[str, str, str, str], tuple[int, int, int]]


def _stored() -> _Sums:
    from backend.crowd.models import CrowdCostTotal

    with session_scope() as session:
        return {(r.scope, r.key, r.kind, r.state): (r.amount_cents, r.fee_cents, r.payments)
                for r in session.scalars(select(CrowdCostTotal)) if r.payments}


def _expected() -> _Sums:
    """The sums over the payment rows, plus the deleted sequences' ledger the workers keep."""
    from backend.crowd.models import CrowdDeletedCost

    with session_scope() as session:
        sums = totals.from_rows(session)
        for row in session.scalars(select(CrowdDeletedCost)):
            key = ("worker", row.worker_id, row.kind, row.state)
            amount, fee, n = sums.get(key, (0, 0, 0))
            sums[key] = (amount + row.amount_cents, fee + row.fee_cents, n + row.payments)
    return sums


def _decided_matches() -> None:
    from backend.annotation.models import Assignment
    from backend.crowd.models import CrowdHit, CrowdPayment

    with session_scope() as session:
        counted = {h: int(n) for h, n in session.execute(select(CrowdHit.hit_id, CrowdHit.decided))}
        rows = {h: int(n) for h, n in session.execute(
            select(Assignment.hit_id, func.count()).join(
                CrowdPayment, CrowdPayment.assignment_id == Assignment.id)
            .where(CrowdPayment.kind.in_(totals.DECISIONS)).group_by(Assignment.hit_id))}
    assert {h: n for h, n in counted.items() if n} == rows


def test_totals_equal_the_payment_rows_through_pays_a_bonus_finished_and_a_delete(
    reviewed: tuple[int, int], api: Any,
) -> None:
    seq_a, _ = reviewed
    assert _stored() == _expected() and _expected()
    _decided_matches()
    with session_scope() as session:  # the pending bonus is confirmed paid
        decisions.finish_bonus(session, decisions.bonus_token(_approved(seq_a), "extra"))
    assert _stored() == _expected()
    assert api.delete(f"/api/sequences/{seq_a}?force=true").status_code == 200
    stored = _stored()
    assert stored == _expected()
    assert not any(scope == "sequence" and key == str(seq_a) for scope, key, *_ in stored)
    _decided_matches()
    with session_scope() as session:  # recomputed from the rows, they come out the same
        totals.rebuild(session)
    assert _stored() == stored
    _decided_matches()


def _approved(sequence_id: int) -> int:
    from backend.annotation.models import Assignment, Task

    with session_scope() as session:
        return int(session.scalar(select(Assignment.id).join(Task).where(
            Task.sequence_id == sequence_id, Assignment.status == "approved")))


@pytest.mark.parametrize("database_url", ["postgres"], indirect=True)
def test_concurrent_payments_add_up_on_postgresql(app_env: dict) -> None:
    from backend.annotation.models import Assignment
    from backend.crowd.models import CrowdPayment
    from tests.backend.crowd.helpers import make_tasks

    task_ids = make_tasks(2)
    with session_scope() as session:
        assignments = []
        for i in range(40):
            row = Assignment(task_id=task_ids[i % 2], worker_id=f"W{i % 3}",
                             external_id=f"A{i}", status="submitted")
            session.add(row)
            session.flush()
            assignments.append((row.id, row.worker_id))
    start = threading.Barrier(8)
    errors: list[BaseException] = []

    def pay(part: list[tuple[int, str]]) -> None:
        try:
            start.wait()
            for n, (assignment_id, worker) in enumerate(part):
                with session_scope() as session:
                    row = CrowdPayment(kind="bonus", assignment_id=assignment_id,
                                       worker_id=worker, request_token=f"bonus-{assignment_id}",
                                       amount_cents=25 + n, fee_cents=5, state="done")
                    session.add(row)
                    totals.record(session, row)
        except BaseException as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=pay, args=(assignments[i::8],)) for i in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors, errors
    stored = _stored()
    assert stored == _expected()
    assert sum(n for (scope, *_), (_, _, n) in stored.items() if scope == "worker") == 40
