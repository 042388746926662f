"""Running totals of the payment ledger for the cost report (crowd_cost_totals per sequence,
worker and provider, and each HIT's ``decided`` count), written in the same transaction as the
payment row they count.

Every write is one atomic statement (an upsert that adds to the stored sums, or an UPDATE
``decided = decided + 1``), so concurrent payments on PostgreSQL add up without a lost update;
a rolled-back payment rolls its totals back with it. A payment row is only ever inserted or
moved from pending to done (the ledger keeps its rows), so ``record`` and ``moved`` are the
whole upkeep; ``rebuild`` recomputes everything from the rows (bulk loads, repairs).
"""

from __future__ import annotations

from sqlalchemy import delete, func, select, text, update
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment, Task
from backend.crowd.models import CrowdCostTotal, CrowdDeletedCost, CrowdHit, CrowdPayment

DECISIONS = ("approval", "rejection")


def _add(session: Session, scope: str, key: str, kind: str, state: str, amount: int, fee: int,
         payments: int) -> None:
    dialect = session.get_bind().dialect.name
    insert = postgresql.insert if dialect == "postgresql" else sqlite.insert
    stmt = insert(CrowdCostTotal).values(scope=scope, key=key, kind=kind, state=state,
                                         amount_cents=amount, fee_cents=fee, payments=payments)
    table = CrowdCostTotal.__table__.c
    session.execute(stmt.on_conflict_do_update(
        index_elements=["scope", "key", "kind", "state"],
        set_={"amount_cents": table.amount_cents + stmt.excluded.amount_cents,
              "fee_cents": table.fee_cents + stmt.excluded.fee_cents,
              "payments": table.payments + stmt.excluded.payments}))


def _count(session: Session, row: CrowdPayment, state: str, sign: int) -> None:
    sequence_id = session.scalar(select(Task.sequence_id).join(
        Assignment, Assignment.task_id == Task.id).where(Assignment.id == row.assignment_id))
    amount, fee = sign * row.amount_cents, sign * row.fee_cents
    _add(session, "sequence", str(sequence_id), row.kind, state, amount, fee, sign)
    _add(session, "worker", row.worker_id, row.kind, state, amount, fee, sign)
    _add(session, "provider", row.provider, row.kind, state, amount, fee, sign)


def record(session: Session, row: CrowdPayment) -> None:
    """Count a payment row just added to the session (flushed here)."""
    session.flush()
    _count(session, row, row.state, 1)
    if row.kind in DECISIONS:
        hit_id = select(Assignment.hit_id).where(Assignment.id == row.assignment_id)
        session.execute(update(CrowdHit).where(CrowdHit.hit_id == hit_id.scalar_subquery())
                        .values(decided=CrowdHit.decided + 1)
                        .execution_options(synchronize_session=False))


def moved(session: Session, row: CrowdPayment, old_state: str) -> None:
    """Move a payment row's sums from ``old_state`` to its current state."""
    if old_state == row.state:
        return
    _count(session, row, old_state, -1)
    _count(session, row, row.state, 1)


def forget_sequence(session: Session, sequence_id: int) -> None:
    """Drop a deleted sequence's own totals (its ledger is kept in crowd_deleted_costs; the
    workers' totals keep its money)."""
    session.execute(delete(CrowdCostTotal).where(
        CrowdCostTotal.scope == "sequence", CrowdCostTotal.key == str(sequence_id))
        .execution_options(synchronize_session=False))


REBUILD_SQL = (
    "DELETE FROM crowd_cost_totals",
    "UPDATE crowd_hits SET decided = 0",
    ("INSERT INTO crowd_cost_totals (scope, key, kind, state, amount_cents, fee_cents, payments) "
     "SELECT 'sequence', CAST(t.sequence_id AS VARCHAR(64)), p.kind, p.state, "
     "SUM(p.amount_cents), SUM(p.fee_cents), COUNT(*) FROM crowd_payments p "
     "JOIN assignments a ON a.id = p.assignment_id JOIN tasks t ON t.id = a.task_id "
     "GROUP BY t.sequence_id, p.kind, p.state"),
    # A worker's totals keep the money of deleted sequences (crowd_deleted_costs).
    ("INSERT INTO crowd_cost_totals (scope, key, kind, state, amount_cents, fee_cents, payments) "
     "SELECT 'worker', x.worker_id, x.kind, x.state, SUM(x.amount), SUM(x.fee), SUM(x.n) "
     "FROM (SELECT worker_id, kind, state, amount_cents AS amount, fee_cents AS fee, 1 AS n "
     "FROM crowd_payments UNION ALL SELECT worker_id, kind, state, amount_cents, fee_cents, "
     "payments FROM crowd_deleted_costs) AS x GROUP BY x.worker_id, x.kind, x.state"),
    # So does a provider's.
    ("INSERT INTO crowd_cost_totals (scope, key, kind, state, amount_cents, fee_cents, payments) "
     "SELECT 'provider', x.provider, x.kind, x.state, SUM(x.amount), SUM(x.fee), SUM(x.n) "
     "FROM (SELECT provider, kind, state, amount_cents AS amount, fee_cents AS fee, 1 AS n "
     "FROM crowd_payments UNION ALL SELECT provider, kind, state, amount_cents, fee_cents, "
     "payments FROM crowd_deleted_costs) AS x GROUP BY x.provider, x.kind, x.state"),
    # One grouped pass (a subquery per HIT would scan the assignments once per HIT).
    ("UPDATE crowd_hits SET decided = d.n FROM (SELECT a.hit_id AS hit_id, COUNT(*) AS n "
     "FROM crowd_payments p JOIN assignments a ON a.id = p.assignment_id "
     "WHERE p.kind IN ('approval', 'rejection') AND a.hit_id IS NOT NULL GROUP BY a.hit_id) "
     "AS d WHERE crowd_hits.hit_id = d.hit_id"),
)


def rebuild(session: Session) -> None:
    """Recompute every total from the payment rows."""
    for statement in REBUILD_SQL:
        session.execute(text(statement))


def from_rows(session: Session) -> dict[tuple[str, str, str, str], tuple[int, int, int]]:
    """The totals as the payment rows give them, summed afresh: what crowd_cost_totals must
    hold (the tests compare the two)."""
    out: dict[tuple[str, str, str, str], tuple[int, int, int]] = {}
    sums = (func.sum(CrowdPayment.amount_cents), func.sum(CrowdPayment.fee_cents), func.count())
    per_sequence = (select(Task.sequence_id, CrowdPayment.kind, CrowdPayment.state, *sums)
                    .join(Assignment, Assignment.id == CrowdPayment.assignment_id)
                    .join(Task, Task.id == Assignment.task_id)
                    .group_by(Task.sequence_id, CrowdPayment.kind, CrowdPayment.state))
    for seq, kind, state, amount, fee, n in session.execute(per_sequence):
        out[("sequence", str(seq), kind, state)] = (int(amount), int(fee), int(n))
    per_worker = (select(CrowdPayment.worker_id, CrowdPayment.kind, CrowdPayment.state, *sums)
                  .group_by(CrowdPayment.worker_id, CrowdPayment.kind, CrowdPayment.state))
    for worker, kind, state, amount, fee, n in session.execute(per_worker):
        out[("worker", worker, kind, state)] = (int(amount), int(fee), int(n))
    _per_provider(session, out)
    return out


def _per_provider(session: Session,
                  out: dict[tuple[str, str, str, str], tuple[int, int, int]]) -> None:
    """A provider's sums keep the money of deleted sequences, as the workers' do."""
    sums = (func.sum(CrowdPayment.amount_cents), func.sum(CrowdPayment.fee_cents), func.count())
    rows = list(session.execute(
        select(CrowdPayment.provider, CrowdPayment.kind, CrowdPayment.state, *sums)
        .group_by(CrowdPayment.provider, CrowdPayment.kind, CrowdPayment.state)))
    rows += session.execute(
        select(CrowdDeletedCost.provider, CrowdDeletedCost.kind, CrowdDeletedCost.state,
               func.sum(CrowdDeletedCost.amount_cents), func.sum(CrowdDeletedCost.fee_cents),
               func.sum(CrowdDeletedCost.payments))
        .group_by(CrowdDeletedCost.provider, CrowdDeletedCost.kind, CrowdDeletedCost.state))
    for provider, kind, state, amount, fee, n in rows:
        key = ("provider", provider, kind, state)
        old = out.get(key, (0, 0, 0))
        out[key] = (old[0] + int(amount), old[1] + int(fee), old[2] + int(n))
