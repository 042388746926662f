"""job progress: how far a long job (an export) has come

``jobs.progress`` holds ``{"done", "total", "stage"}`` while a job that reports progress runs,
and its final counts once it ends; None for jobs that report none.

Revision ID: 0013
Revises: 0012
Create Date: 2026-12-10 12:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0013'
down_revision = '0012'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('jobs') as batch:
        batch.add_column(sa.Column('progress', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('jobs') as batch:
        batch.drop_column('progress')
