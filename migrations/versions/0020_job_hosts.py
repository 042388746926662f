"""jobs record the host that ran them, and each attempt's actions

``jobs.host`` names the host (``name:pid``) whose attempt last claimed the job;
``jobs.attempt_log`` lists the current run's attempts, each with its number, host, start time
and the actions it recorded (a job retried after a killed worker reports them all).

Revision ID: 0020
Revises: 0019
Create Date: 2026-12-04 11:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0020'
down_revision = '0019'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('jobs') as batch:
        batch.add_column(sa.Column('host', sa.String(length=255), nullable=True))
        batch.add_column(sa.Column('attempt_log', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('jobs') as batch:
        batch.drop_column('attempt_log')
        batch.drop_column('host')
