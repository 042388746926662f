"""crowd: views published where the 3D needs them

``crowd_hits.reason``: why a unit was published under the adaptive policy (null: every view at
once, as before). ``crowd_publish_plans``: per sequence, the publishing policy, its numbers and
the publish options that the publishes after each solve use again.

Revision ID: 0024
Revises: 0023
Create Date: 2026-12-04 21:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0024'
down_revision = '0023'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('crowd_hits') as batch:
        batch.add_column(sa.Column('reason', sa.String(length=300), nullable=True))
    op.create_table(
        'crowd_publish_plans',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('sequence_id', sa.Integer(), nullable=False),
        sa.Column('policy', sa.String(length=16), nullable=False),
        sa.Column('initial_views', sa.Integer(), nullable=False),
        sa.Column('confidence', sa.Float(), nullable=False),
        sa.Column('confident_share', sa.Float(), nullable=False),
        sa.Column('options', sa.JSON(), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.CheckConstraint("policy IN ('every-view', 'adaptive')",
                           name=op.f('ck_crowd_publish_plans_policy_valid')),
        sa.CheckConstraint('initial_views >= 2',
                           name=op.f('ck_crowd_publish_plans_initial_views_at_least_two')),
        sa.ForeignKeyConstraint(['sequence_id'], ['sequences.id'],
                                name=op.f('fk_crowd_publish_plans_sequence_id_sequences'),
                                ondelete='CASCADE'),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_crowd_publish_plans')),
        sa.UniqueConstraint('sequence_id', name=op.f('uq_crowd_publish_plans_sequence_id')),
    )


def downgrade() -> None:
    op.drop_table('crowd_publish_plans')
    with op.batch_alter_table('crowd_hits') as batch:
        batch.drop_column('reason')
