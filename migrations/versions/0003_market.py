"""market: HIT types, HITs, assignments, bonuses, qualifications, blocks, ledger

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-23 12:17:45.087999
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0003'
down_revision = '0002'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('market_hit_types',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('type_id', sa.String(length=64), nullable=False),
    sa.Column('group_id', sa.String(length=64), nullable=False),
    sa.Column('requester', sa.String(length=128), nullable=False),
    sa.Column('fingerprint', sa.String(length=64), nullable=False),
    sa.Column('title', sa.String(length=128), nullable=False),
    sa.Column('description', sa.Text(), nullable=False),
    sa.Column('keywords', sa.Text(), nullable=True),
    sa.Column('reward_cents', sa.BigInteger(), nullable=False),
    sa.Column('assignment_duration_s', sa.BigInteger(), nullable=False),
    sa.Column('auto_approval_delay_s', sa.BigInteger(), nullable=False),
    sa.Column('qualification_requirements', sa.JSON(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint('reward_cents >= 0', name=op.f('ck_market_hit_types_reward_nonnegative')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_hit_types')),
    sa.UniqueConstraint('requester', 'fingerprint', name=op.f('uq_market_hit_types_requester_fingerprint')),
    sa.UniqueConstraint('type_id', name=op.f('uq_market_hit_types_type_id'))
    )
    op.create_index(op.f('ix_market_hit_types_requester'), 'market_hit_types', ['requester'], unique=False)

    op.create_table('market_notifications',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('requester', sa.String(length=128), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('subject', sa.String(length=200), nullable=False),
    sa.Column('message', sa.Text(), nullable=False),
    sa.Column('sent_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_notifications'))
    )
    op.create_index(op.f('ix_market_notifications_worker_id'), 'market_notifications', ['worker_id'], unique=False)

    op.create_table('market_qualification_types',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('type_id', sa.String(length=64), nullable=False),
    sa.Column('requester', sa.String(length=128), nullable=False),
    sa.Column('name', sa.String(length=255), nullable=False),
    sa.Column('description', sa.Text(), nullable=False),
    sa.Column('keywords', sa.Text(), nullable=True),
    sa.Column('status', sa.String(length=8), nullable=False),
    sa.Column('retry_delay_s', sa.BigInteger(), nullable=True),
    sa.Column('test', sa.Text(), nullable=True),
    sa.Column('answer_key', sa.Text(), nullable=True),
    sa.Column('test_duration_s', sa.BigInteger(), nullable=True),
    sa.Column('auto_granted', sa.Boolean(), nullable=False),
    sa.Column('auto_granted_value', sa.Integer(), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint("status IN ('Active', 'Inactive')", name=op.f('ck_market_qualification_types_status_valid')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_qualification_types')),
    sa.UniqueConstraint('requester', 'name', name=op.f('uq_market_qualification_types_requester_name')),
    sa.UniqueConstraint('type_id', name=op.f('uq_market_qualification_types_type_id'))
    )
    op.create_index(op.f('ix_market_qualification_types_requester'), 'market_qualification_types', ['requester'], unique=False)

    op.create_table('market_request_tokens',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('requester', sa.String(length=128), nullable=False),
    sa.Column('operation', sa.String(length=64), nullable=False),
    sa.Column('token', sa.String(length=64), nullable=False),
    sa.Column('request_id', sa.String(length=64), nullable=False),
    sa.Column('entity_id', sa.String(length=64), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_request_tokens')),
    sa.UniqueConstraint('requester', 'operation', 'token', name=op.f('uq_market_request_tokens_requester_operation_token'))
    )
    op.create_table('market_worker_blocks',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('requester', sa.String(length=128), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('reason', sa.Text(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_worker_blocks')),
    sa.UniqueConstraint('requester', 'worker_id', name=op.f('uq_market_worker_blocks_requester_worker_id'))
    )
    op.create_index(op.f('ix_market_worker_blocks_worker_id'), 'market_worker_blocks', ['worker_id'], unique=False)

    op.create_table('market_workers',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('locale_country', sa.String(length=2), nullable=True),
    sa.Column('locale_subdivision', sa.String(length=3), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_workers')),
    sa.UniqueConstraint('worker_id', name=op.f('uq_market_workers_worker_id'))
    )
    op.create_table('market_hits',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('hit_id', sa.String(length=64), nullable=False),
    sa.Column('requester', sa.String(length=128), nullable=False),
    sa.Column('hit_type_pk', sa.Integer(), nullable=False),
    sa.Column('question', sa.Text(), nullable=False),
    sa.Column('requester_annotation', sa.Text(), nullable=True),
    sa.Column('max_assignments', sa.Integer(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('expiration', sa.DateTime(timezone=True), nullable=False),
    sa.Column('disposed_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('reviewing', sa.Boolean(), nullable=False),
    sa.Column('held_slots', sa.Integer(), nullable=False),
    sa.Column('settled', sa.Boolean(), nullable=False),
    sa.Column('version', sa.Integer(), nullable=False),
    sa.CheckConstraint('held_slots >= 0', name=op.f('ck_market_hits_held_slots_nonnegative')),
    sa.CheckConstraint('max_assignments >= 1', name=op.f('ck_market_hits_max_assignments_positive')),
    sa.ForeignKeyConstraint(['hit_type_pk'], ['market_hit_types.id'], name=op.f('fk_market_hits_hit_type_pk_market_hit_types')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_hits')),
    sa.UniqueConstraint('hit_id', name=op.f('uq_market_hits_hit_id'))
    )
    op.create_index(op.f('ix_market_hits_hit_type_pk'), 'market_hits', ['hit_type_pk'], unique=False)
    op.create_index(op.f('ix_market_hits_requester'), 'market_hits', ['requester'], unique=False)
    op.create_index('ix_market_hits_settled_expiration', 'market_hits', ['settled', 'expiration'], unique=False)

    op.create_table('market_qualifications',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('type_pk', sa.Integer(), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('integer_value', sa.Integer(), nullable=True),
    sa.Column('status', sa.String(length=8), nullable=False),
    sa.Column('grant_time', sa.DateTime(timezone=True), nullable=False),
    sa.Column('revoke_reason', sa.Text(), nullable=True),
    sa.CheckConstraint("status IN ('Granted', 'Revoked')", name=op.f('ck_market_qualifications_status_valid')),
    sa.ForeignKeyConstraint(['type_pk'], ['market_qualification_types.id'], name=op.f('fk_market_qualifications_type_pk_market_qualification_types')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_qualifications')),
    sa.UniqueConstraint('type_pk', 'worker_id', name=op.f('uq_market_qualifications_type_pk_worker_id'))
    )
    op.create_index(op.f('ix_market_qualifications_worker_id'), 'market_qualifications', ['worker_id'], unique=False)

    op.create_table('market_assignments',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('assignment_id', sa.String(length=64), nullable=False),
    sa.Column('hit_pk', sa.Integer(), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('accept_time', sa.DateTime(timezone=True), nullable=False),
    sa.Column('deadline', sa.DateTime(timezone=True), nullable=False),
    sa.Column('submit_time', sa.DateTime(timezone=True), nullable=True),
    sa.Column('auto_approval_time', sa.DateTime(timezone=True), nullable=True),
    sa.Column('approval_time', sa.DateTime(timezone=True), nullable=True),
    sa.Column('rejection_time', sa.DateTime(timezone=True), nullable=True),
    sa.Column('answer', sa.Text(), nullable=True),
    sa.Column('requester_feedback', sa.Text(), nullable=True),
    sa.CheckConstraint("status IN ('Accepted', 'Submitted', 'Approved', 'Rejected', 'Returned', 'Abandoned')", name=op.f('ck_market_assignments_status_valid')),
    sa.ForeignKeyConstraint(['hit_pk'], ['market_hits.id'], name=op.f('fk_market_assignments_hit_pk_market_hits')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_assignments')),
    sa.UniqueConstraint('assignment_id', name=op.f('uq_market_assignments_assignment_id'))
    )
    op.create_index(op.f('ix_market_assignments_hit_pk'), 'market_assignments', ['hit_pk'], unique=False)
    op.create_index('ix_market_assignments_status_auto_approval_time', 'market_assignments', ['status', 'auto_approval_time'], unique=False)
    op.create_index('ix_market_assignments_status_deadline', 'market_assignments', ['status', 'deadline'], unique=False)
    op.create_index(op.f('ix_market_assignments_worker_id'), 'market_assignments', ['worker_id'], unique=False)

    op.create_table('market_bonuses',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('requester', sa.String(length=128), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('assignment_pk', sa.Integer(), nullable=False),
    sa.Column('amount_cents', sa.BigInteger(), nullable=False),
    sa.Column('reason', sa.Text(), nullable=False),
    sa.Column('grant_time', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint('amount_cents > 0', name=op.f('ck_market_bonuses_amount_positive')),
    sa.ForeignKeyConstraint(['assignment_pk'], ['market_assignments.id'], name=op.f('fk_market_bonuses_assignment_pk_market_assignments')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_bonuses'))
    )
    op.create_index(op.f('ix_market_bonuses_assignment_pk'), 'market_bonuses', ['assignment_pk'], unique=False)
    op.create_index(op.f('ix_market_bonuses_requester'), 'market_bonuses', ['requester'], unique=False)
    op.create_index(op.f('ix_market_bonuses_worker_id'), 'market_bonuses', ['worker_id'], unique=False)

    op.create_table('market_ledger',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('requester', sa.String(length=128), nullable=False),
    sa.Column('kind', sa.String(length=16), nullable=False),
    sa.Column('available_cents', sa.BigInteger(), nullable=False),
    sa.Column('held_cents', sa.BigInteger(), nullable=False),
    sa.Column('hit_pk', sa.Integer(), nullable=True),
    sa.Column('assignment_pk', sa.Integer(), nullable=True),
    sa.Column('bonus_pk', sa.Integer(), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint("kind IN ('hold', 'release', 'pay', 'bonus')", name=op.f('ck_market_ledger_kind_valid')),
    sa.ForeignKeyConstraint(['assignment_pk'], ['market_assignments.id'], name=op.f('fk_market_ledger_assignment_pk_market_assignments')),
    sa.ForeignKeyConstraint(['bonus_pk'], ['market_bonuses.id'], name=op.f('fk_market_ledger_bonus_pk_market_bonuses')),
    sa.ForeignKeyConstraint(['hit_pk'], ['market_hits.id'], name=op.f('fk_market_ledger_hit_pk_market_hits')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_market_ledger'))
    )
    op.create_index(op.f('ix_market_ledger_hit_pk'), 'market_ledger', ['hit_pk'], unique=False)
    op.create_index(op.f('ix_market_ledger_requester'), 'market_ledger', ['requester'], unique=False)


def downgrade() -> None:
    op.drop_table('market_ledger')
    op.drop_table('market_bonuses')
    op.drop_table('market_assignments')
    op.drop_table('market_qualifications')
    op.drop_table('market_hits')
    op.drop_table('market_workers')
    op.drop_table('market_worker_blocks')
    op.drop_table('market_request_tokens')
    op.drop_table('market_qualification_types')
    op.drop_table('market_notifications')
    op.drop_table('market_hit_types')
