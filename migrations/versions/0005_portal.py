"""portal: worker accounts and invites

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-23 12:40:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0005'
down_revision = '0004'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('portal_accounts',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('email', sa.String(length=320), nullable=False),
    sa.Column('password_hash', sa.String(length=300), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('active', sa.Boolean(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['worker_id'], ['market_workers.worker_id'], name=op.f('fk_portal_accounts_worker_id_market_workers')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_portal_accounts')),
    sa.UniqueConstraint('email', name=op.f('uq_portal_accounts_email')),
    sa.UniqueConstraint('worker_id', name=op.f('uq_portal_accounts_worker_id'))
    )
    op.create_table('portal_invites',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('token_hash', sa.String(length=64), nullable=False),
    sa.Column('created_by', sa.Integer(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('expires_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('used_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('account_id', sa.Integer(), nullable=True),
    sa.ForeignKeyConstraint(['account_id'], ['portal_accounts.id'], name=op.f('fk_portal_invites_account_id_portal_accounts')),
    sa.ForeignKeyConstraint(['created_by'], ['admins.id'], name=op.f('fk_portal_invites_created_by_admins')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_portal_invites')),
    sa.UniqueConstraint('token_hash', name=op.f('uq_portal_invites_token_hash'))
    )
    op.create_index(op.f('ix_portal_invites_account_id'), 'portal_invites', ['account_id'], unique=False)
    op.create_index(op.f('ix_portal_invites_created_by'), 'portal_invites', ['created_by'], unique=False)


def downgrade() -> None:
    op.drop_index(op.f('ix_portal_invites_created_by'), table_name='portal_invites')
    op.drop_index(op.f('ix_portal_invites_account_id'), table_name='portal_invites')
    op.drop_table('portal_invites')
    op.drop_table('portal_accounts')
