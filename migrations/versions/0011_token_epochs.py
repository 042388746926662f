"""token epochs: signing out and password changes end every token of an account

``admins.token_epoch`` and ``portal_accounts.token_epoch`` are copied into each bearer token the
account gets; a token whose epoch is not the account's current one is refused. Logging out and
changing or resetting the password move the epoch on.

Revision ID: 0011
Revises: 0010
Create Date: 2026-12-03 09:00:00
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0011'
down_revision = '0010'
branch_labels = None
depends_on = None

TABLES = ('admins', 'portal_accounts')


def upgrade() -> None:
    for table in TABLES:
        with op.batch_alter_table(table, schema=None) as batch_op:
            batch_op.add_column(sa.Column('token_epoch', sa.Integer(), nullable=False,
                                          server_default='0'))


def downgrade() -> None:
    for table in TABLES:
        with op.batch_alter_table(table, schema=None) as batch_op:
            batch_op.drop_column('token_epoch')
