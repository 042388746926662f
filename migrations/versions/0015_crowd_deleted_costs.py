"""crowd deleted costs: the ledger of a sequence deleted with its work, kept for the cost report

A forced sequence delete removes its payment rows with its assignments; what they held (per
worker, kind and state: cents, fees, how many) is written here first, so money spent never
leaves ``GET /api/crowd/costs``.

Revision ID: 0015
Revises: 0014
Create Date: 2026-12-02 20:45:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0015'
down_revision = '0014'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        'crowd_deleted_costs',
        sa.Column('id', sa.Integer(), primary_key=True),
        sa.Column('sequence_id', sa.Integer(), nullable=False),
        sa.Column('sequence_name', sa.String(300), nullable=False),
        sa.Column('worker_id', sa.String(64), nullable=False),
        sa.Column('kind', sa.String(16), nullable=False),
        sa.Column('state', sa.String(16), nullable=False),
        sa.Column('amount_cents', sa.BigInteger(), nullable=False),
        sa.Column('fee_cents', sa.BigInteger(), nullable=False),
        sa.Column('payments', sa.Integer(), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    )


def downgrade() -> None:
    op.drop_table('crowd_deleted_costs')
