"""calibration versions: refined calibrations beside the imported one

``calibration_versions`` holds numbered refinements of a sequence's rig (extrinsics, time
offsets, depth scale and shift per camera serial) with the rig-health report behind each; the
imported calibration stays in ``cameras``. At most one version per sequence is in use.

Revision ID: 0018
Revises: 0017
Create Date: 2026-12-03 16:30:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0018'
down_revision = '0017'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        'calibration_versions',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('sequence_id', sa.Integer(), nullable=False),
        sa.Column('number', sa.Integer(), nullable=False),
        sa.Column('source', sa.String(length=32), nullable=False),
        sa.Column('in_use', sa.Boolean(), nullable=False),
        sa.Column('cameras', sa.JSON(), nullable=False),
        sa.Column('report', sa.JSON(), nullable=False),
            sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(['sequence_id'], ['sequences.id'], ondelete='CASCADE'),
        sa.PrimaryKeyConstraint('id'),
        sa.UniqueConstraint('sequence_id', 'number'),
    )
    op.create_index('ix_calibration_versions_sequence_id', 'calibration_versions',
                    ['sequence_id'])
    op.create_index('ux_calibration_versions_in_use', 'calibration_versions', ['sequence_id'],
                    unique=True, postgresql_where=sa.text('in_use'),
                    sqlite_where=sa.text('in_use'))


def downgrade() -> None:
    op.drop_index('ux_calibration_versions_in_use', table_name='calibration_versions')
    op.drop_index('ix_calibration_versions_sequence_id', table_name='calibration_versions')
    op.drop_table('calibration_versions')
