"""crowd: published HITs, verified submissions, payment ledger, qualifications, worker actions

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-23 12:50:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0004'
down_revision = '0003'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('crowd_qualifications',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=128), nullable=False),
    sa.Column('qualification_type_id', sa.String(length=64), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_crowd_qualifications')),
    sa.UniqueConstraint('name', name=op.f('uq_crowd_qualifications_name')),
    sa.UniqueConstraint('qualification_type_id', name=op.f('uq_crowd_qualifications_qualification_type_id'))
    )
    op.create_table('crowd_worker_actions',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('kind', sa.String(length=16), nullable=False),
    sa.Column('target', sa.String(length=64), nullable=False),
    sa.Column('value', sa.Integer(), nullable=True),
    sa.Column('reason', sa.Text(), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint("kind IN ('block', 'qualification')", name=op.f('ck_crowd_worker_actions_kind_valid')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_crowd_worker_actions')),
    sa.UniqueConstraint('worker_id', 'kind', 'target', name=op.f('uq_crowd_worker_actions_worker_id_kind_target'))
    )
    op.create_table('crowd_hits',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('task_id', sa.Integer(), nullable=False),
    sa.Column('round', sa.Integer(), nullable=False),
    sa.Column('request_token', sa.String(length=64), nullable=False),
    sa.Column('hit_id', sa.String(length=64), nullable=True),
    sa.Column('max_assignments', sa.Integer(), nullable=False),
    sa.Column('reward_cents', sa.Integer(), nullable=False),
    sa.Column('expired_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint('max_assignments >= 1', name=op.f('ck_crowd_hits_max_assignments_positive')),
    sa.CheckConstraint('round >= 1', name=op.f('ck_crowd_hits_round_positive')),
    sa.ForeignKeyConstraint(['task_id'], ['tasks.id'], name=op.f('fk_crowd_hits_task_id_tasks'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_crowd_hits')),
    sa.UniqueConstraint('hit_id', name=op.f('uq_crowd_hits_hit_id')),
    sa.UniqueConstraint('request_token', name=op.f('uq_crowd_hits_request_token')),
    sa.UniqueConstraint('task_id', 'round', name=op.f('uq_crowd_hits_task_id_round'))
    )
    op.create_table('crowd_payments',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('kind', sa.String(length=16), nullable=False),
    sa.Column('assignment_id', sa.Integer(), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('request_token', sa.String(length=64), nullable=False),
    sa.Column('amount_cents', sa.Integer(), nullable=False),
    sa.Column('fee_cents', sa.Integer(), nullable=False),
    sa.Column('feedback', sa.Text(), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint("kind IN ('approval', 'rejection', 'bonus')", name=op.f('ck_crowd_payments_kind_valid')),
    sa.CheckConstraint('amount_cents >= 0 AND fee_cents >= 0', name=op.f('ck_crowd_payments_amounts_nonnegative')),
    sa.ForeignKeyConstraint(['assignment_id'], ['assignments.id'], name=op.f('fk_crowd_payments_assignment_id_assignments'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_crowd_payments')),
    sa.UniqueConstraint('request_token', name=op.f('uq_crowd_payments_request_token'))
    )
    op.create_table('crowd_submissions',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('assignment_id', sa.Integer(), nullable=False),
    sa.Column('hit_id', sa.String(length=64), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('market_status', sa.String(length=16), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['assignment_id'], ['assignments.id'], name=op.f('fk_crowd_submissions_assignment_id_assignments'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_crowd_submissions')),
    sa.UniqueConstraint('assignment_id', name=op.f('uq_crowd_submissions_assignment_id'))
    )
    # ### end Alembic commands ###
    op.create_index(op.f('ix_crowd_payments_assignment_id'), 'crowd_payments', ['assignment_id'], unique=False)
    op.create_index(op.f('ix_crowd_payments_worker_id'), 'crowd_payments', ['worker_id'], unique=False)


def downgrade() -> None:
    op.drop_index(op.f('ix_crowd_payments_worker_id'), table_name='crowd_payments')
    op.drop_index(op.f('ix_crowd_payments_assignment_id'), table_name='crowd_payments')
    op.drop_table('crowd_submissions')
    op.drop_table('crowd_payments')
    op.drop_table('crowd_hits')
    op.drop_table('crowd_worker_actions')
    op.drop_table('crowd_qualifications')
