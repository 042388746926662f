"""qc report replay: what a reviewer's replay of an assignment draws

``qc_reports.replay`` holds the reference pixels each label is judged against (the other
views' leave-one-out consensus, or the solved object's anchored landmarks), the error matrix
(frames x points, px) and the issue spans; None for reports scored before it was stored.

Revision ID: 0014
Revises: 0013
Create Date: 2026-12-12 12:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0014'
down_revision = '0013'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('qc_reports') as batch:
        batch.add_column(sa.Column('replay', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('qc_reports') as batch:
        batch.drop_column('replay')
