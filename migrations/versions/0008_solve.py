"""solve runs: one row per request to fit a sequence's hand and object poses

Revision ID: 0008
Revises: 0007
Create Date: 2026-11-23 13:46:41
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0008'
down_revision = '0007'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('solve_runs',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('sequence_id', sa.Integer(), nullable=False),
    sa.Column('optimiser', sa.String(length=16), nullable=False),
    sa.Column('params', sa.JSON(), nullable=False),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('timings', sa.JSON(), nullable=False),
    sa.Column('summary', sa.JSON(), nullable=True),
    sa.Column('error', sa.Text(), nullable=True),
    sa.Column('result_key', sa.String(length=500), nullable=True),
    sa.Column('num_frames', sa.Integer(), nullable=False),
    sa.Column('num_views', sa.Integer(), nullable=False),
    sa.Column('started_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('finished_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint("optimiser IN ('paper', 'default')", name=op.f('ck_solve_runs_optimiser_valid')),
    sa.CheckConstraint("status IN ('queued', 'running', 'done', 'failed')", name=op.f('ck_solve_runs_status_valid')),
    sa.ForeignKeyConstraint(['sequence_id'], ['sequences.id'], name=op.f('fk_solve_runs_sequence_id_sequences'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_solve_runs'))
    )
    with op.batch_alter_table('solve_runs', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_solve_runs_sequence_id'), ['sequence_id'], unique=False)
        batch_op.create_index(batch_op.f('ix_solve_runs_status'), ['status'], unique=False)


def downgrade() -> None:
    with op.batch_alter_table('solve_runs', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_solve_runs_status'))
        batch_op.drop_index(batch_op.f('ix_solve_runs_sequence_id'))

    op.drop_table('solve_runs')
