"""crowd: payment ledger rows written before the marketplace call (pending, then done)

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-23 13:45:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0006'
down_revision = '0005'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('crowd_payments') as batch:
        batch.add_column(sa.Column('state', sa.String(length=16), nullable=False,
                                   server_default='done'))
        batch.create_check_constraint('state_valid', "state IN ('pending', 'done')")


def downgrade() -> None:
    with op.batch_alter_table('crowd_payments') as batch:
        batch.drop_constraint(op.f('ck_crowd_payments_state_valid'), type_='check')
        batch.drop_column('state')
