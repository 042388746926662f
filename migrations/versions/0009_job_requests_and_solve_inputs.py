"""job re-run requests and the labels a solve run was made from

A job asked for while it runs is run again once it finishes: ``requests`` counts the asks,
``requests_claimed`` the count the running attempt started from. A solve run records a digest
of the accepted assignments it was requested for, so the pipeline asks for one solve per set
of accepted labels.

Revision ID: 0009
Revises: 0008
Create Date: 2026-12-01 21:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0009'
down_revision = '0008'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('jobs', schema=None) as batch_op:
        batch_op.add_column(sa.Column('requests', sa.Integer(), nullable=False,
                                      server_default='0'))
        batch_op.add_column(sa.Column('requests_claimed', sa.Integer(), nullable=False,
                                      server_default='0'))
    with op.batch_alter_table('solve_runs', schema=None) as batch_op:
        batch_op.add_column(sa.Column('labels_digest', sa.String(length=64), nullable=True))
        batch_op.create_index(batch_op.f('ix_solve_runs_labels_digest'), ['labels_digest'],
                              unique=False)


def downgrade() -> None:
    with op.batch_alter_table('solve_runs', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_solve_runs_labels_digest'))
        batch_op.drop_column('labels_digest')
    with op.batch_alter_table('jobs', schema=None) as batch_op:
        batch_op.drop_column('requests_claimed')
        batch_op.drop_column('requests')
