"""crowd hits open index: the HITs with open slots, for the cost report's committed money

A partial index on ``crowd_hits (task_id)`` over the live HITs with fewer decisions than
assignments: a few hundred of the ~40,000 HITs of a DexYCB-sized project.

Revision ID: 0017
Revises: 0016
Create Date: 2026-12-02 20:35:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0017'
down_revision = '0016'
branch_labels = None
depends_on = None

OPEN_SLOTS = "hit_id IS NOT NULL AND expired_at IS NULL AND max_assignments > decided"


def upgrade() -> None:
    op.create_index('ix_crowd_hits_open_task_id', 'crowd_hits', ['task_id'],
                    postgresql_where=sa.text(OPEN_SLOTS), sqlite_where=sa.text(OPEN_SLOTS))


def downgrade() -> None:
    op.drop_index('ix_crowd_hits_open_task_id', table_name='crowd_hits')
