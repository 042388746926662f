"""crowd providers: every row that points at a crowd names its provider

``provider`` (mturk, prolific, team) on crowd_hits, crowd_submissions, crowd_payments,
crowd_worker_actions, crowd_deleted_costs and assignments; the rows already there are MTurk's
(the only crowd before). Their id columns (hit_id, external_id, worker_id, target) keep their
names and hold the provider's opaque ids. crowd_cost_totals gains the scope "provider" (the cost
report per provider), filled from the workers' totals, which hold the whole ledger.

Revision ID: 0021
Revises: 0020
Create Date: 2026-12-04 14:00:00
"""

from __future__ import annotations

from typing import Any

import sqlalchemy as sa
from alembic import op

revision = '0021'
down_revision = '0020'
branch_labels = None
depends_on = None

TABLES = ('crowd_hits', 'crowd_submissions', 'crowd_payments', 'crowd_worker_actions',
          'crowd_deleted_costs', 'assignments')
FILL = ("INSERT INTO crowd_cost_totals (scope, key, kind, state, amount_cents, fee_cents, "
        "payments) SELECT 'provider', 'mturk', kind, state, SUM(amount_cents), SUM(fee_cents), "
        "SUM(payments) FROM crowd_cost_totals WHERE scope = 'worker' GROUP BY kind, state")


def _scopes(batch: Any, scopes: str) -> None:
    batch.drop_constraint(op.f('ck_crowd_cost_totals_scope_valid'), type_='check')
    batch.create_check_constraint(op.f('ck_crowd_cost_totals_scope_valid'),
                                  f"scope IN ({scopes})")


def upgrade() -> None:
    for table in TABLES:
        with op.batch_alter_table(table) as batch:
            batch.add_column(sa.Column('provider', sa.String(length=16), nullable=False,
                                       server_default='mturk'))
    with op.batch_alter_table('crowd_cost_totals') as batch:
        _scopes(batch, "'sequence', 'worker', 'provider'")
    op.execute(FILL)


def downgrade() -> None:
    op.execute("DELETE FROM crowd_cost_totals WHERE scope = 'provider'")
    with op.batch_alter_table('crowd_cost_totals') as batch:
        _scopes(batch, "'sequence', 'worker'")
    for table in reversed(TABLES):
        with op.batch_alter_table(table) as batch:
            batch.drop_column('provider')
