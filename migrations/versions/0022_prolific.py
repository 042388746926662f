"""prolific: our records of Taskflow studies, their units, bonuses, webhooks and the wallet lease

Revision ID: 0022
Revises: 0021
Create Date: 2026-12-04 14:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0022'
down_revision = '0021'
branch_labels = None
depends_on = None


def _created_at() -> sa.Column:
    return sa.Column('created_at', sa.DateTime(timezone=True), nullable=False)


def upgrade() -> None:
    op.create_table(
        'prolific_studies',
        sa.Column('id', sa.Integer(), primary_key=True),
        sa.Column('batch_key', sa.String(64), nullable=False, unique=True),
        sa.Column('internal_name', sa.String(128), nullable=False, unique=True),
        sa.Column('study_id', sa.String(64), nullable=True, unique=True),
        sa.Column('state', sa.String(16), nullable=False),
        sa.Column('completion_code', sa.String(32), nullable=False),
        sa.Column('reward_cents', sa.Integer(), nullable=False),
        sa.Column('allotted_s', sa.Integer(), nullable=False),
        sa.Column('status', sa.String(32), nullable=True),
        _created_at(),
        sa.CheckConstraint("state IN ('creating', 'created', 'coded', 'published')",
                           name='state_valid'),
    )
    op.create_table(
        'prolific_units',
        sa.Column('id', sa.Integer(), primary_key=True),
        sa.Column('study_row_id', sa.Integer(),
                  sa.ForeignKey('prolific_studies.id', ondelete='CASCADE'), nullable=False),
        sa.Column('key', sa.String(64), nullable=False, unique=True),
        sa.Column('position', sa.Integer(), nullable=False),
        sa.Column('task_id', sa.Integer(), nullable=False),
        sa.Column('places', sa.Integer(), nullable=False),
        sa.Column('external_url', sa.String(2000), nullable=False),
        sa.Column('place_keys', sa.JSON(), nullable=False),
        sa.Column('closed_at', sa.DateTime(timezone=True), nullable=True),
        _created_at(),
        sa.UniqueConstraint('study_row_id', 'position'),
    )
    op.create_index('ix_prolific_units_study_row_id', 'prolific_units', ['study_row_id'])
    op.create_table(
        'prolific_bonuses',
        sa.Column('id', sa.Integer(), primary_key=True),
        sa.Column('key', sa.String(64), nullable=False, unique=True),
        sa.Column('study_id', sa.String(64), nullable=False),
        sa.Column('submission_id', sa.String(64), nullable=False),
        sa.Column('participant_id', sa.String(64), nullable=False),
        sa.Column('amount_cents', sa.Integer(), nullable=False),
        sa.Column('bulk_id', sa.String(64), nullable=True),
        sa.Column('state', sa.String(16), nullable=False),
        _created_at(),
        sa.CheckConstraint("state IN ('created', 'paying', 'paid')", name='state_valid'),
    )
    op.create_table(
        'prolific_webhook_events',
        sa.Column('id', sa.Integer(), primary_key=True),
        sa.Column('digest', sa.String(64), nullable=False, unique=True),
        sa.Column('event_type', sa.String(64), nullable=False),
        sa.Column('resource_id', sa.String(64), nullable=False),
        _created_at(),
    )
    op.create_table(
        'prolific_leases',
        sa.Column('name', sa.String(32), primary_key=True),
        sa.Column('holder', sa.String(64), nullable=True),
        sa.Column('until', sa.DateTime(timezone=True), nullable=True),
    )


def downgrade() -> None:
    for table in ('prolific_leases', 'prolific_webhook_events', 'prolific_bonuses',
                  'prolific_units', 'prolific_studies'):
        op.drop_table(table)
