"""crowd cost totals: running sums of the payment ledger for the cost report

``crowd_cost_totals`` holds the ledger's sums per sequence and per worker by kind and state,
and ``crowd_hits.decided`` each HIT's approvals and rejections; both are written with each
payment row (backend.crowd.totals) and filled here from the rows already there.

Revision ID: 0016
Revises: 0015
Create Date: 2026-12-02 20:20:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0016'
down_revision = '0015'
branch_labels = None
depends_on = None

FILL = (
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
    # One grouped pass (a subquery per HIT would scan the assignments once per HIT).
    ("UPDATE crowd_hits SET decided = d.n FROM (SELECT a.hit_id AS hit_id, COUNT(*) AS n "
     "FROM crowd_payments p JOIN assignments a ON a.id = p.assignment_id "
     "WHERE p.kind IN ('approval', 'rejection') AND a.hit_id IS NOT NULL GROUP BY a.hit_id) "
     "AS d WHERE crowd_hits.hit_id = d.hit_id"),
)


def upgrade() -> None:
    op.create_table(
        'crowd_cost_totals',
        sa.Column('id', sa.Integer(), primary_key=True),
        sa.Column('scope', sa.String(16), nullable=False),
        sa.Column('key', sa.String(64), nullable=False),
        sa.Column('kind', sa.String(16), nullable=False),
        sa.Column('state', sa.String(16), nullable=False),
        sa.Column('amount_cents', sa.BigInteger(), nullable=False),
        sa.Column('fee_cents', sa.BigInteger(), nullable=False),
        sa.Column('payments', sa.Integer(), nullable=False),
        sa.UniqueConstraint('scope', 'key', 'kind', 'state',
                            name=op.f('uq_crowd_cost_totals_scope_key_kind_state')),
        sa.CheckConstraint("scope IN ('sequence', 'worker')",
                           name=op.f('ck_crowd_cost_totals_scope_valid')),
    )
    with op.batch_alter_table('crowd_hits') as batch:
        batch.add_column(sa.Column('decided', sa.Integer(), nullable=False, server_default='0'))
    for statement in FILL:
        op.execute(statement)


def downgrade() -> None:
    with op.batch_alter_table('crowd_hits') as batch:
        batch.drop_column('decided')
    op.drop_table('crowd_cost_totals')
