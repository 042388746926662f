"""calibration versions carry a refined hand shape

``calibration_versions.hands`` holds, per hand index, the betas a rig-health estimate fitted to
the accepted labels where the calibration's hand shape was named off; NULL (or a hand missing)
means the hand's imported betas.

Revision ID: 0019
Revises: 0018
Create Date: 2026-12-03 21:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0019'
down_revision = '0018'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('calibration_versions') as batch:
        batch.add_column(sa.Column('hands', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('calibration_versions') as batch:
        batch.drop_column('hands')
