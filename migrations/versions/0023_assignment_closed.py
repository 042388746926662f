"""assignments: a "closed" status for work an admin closed while it was still being done

Work left "working" (a direct link never finished, a worker who walked away) holds a place of
its unit; an admin closes it from the admin page: its place is free again, its saved labels stay.

Revision ID: 0023
Revises: 0022
Create Date: 2026-12-04 14:00:00
"""

from __future__ import annotations

from alembic import op

revision = '0023'
down_revision = '0022'
branch_labels = None
depends_on = None

_BEFORE = "status IN ('working', 'submitted', 'approved', 'rejected')"
_AFTER = "status IN ('working', 'submitted', 'approved', 'rejected', 'closed')"


def _status_check(check: str) -> None:
    with op.batch_alter_table('assignments') as batch:
        batch.drop_constraint(op.f('ck_assignments_status_valid'), type_='check')
        batch.create_check_constraint('status_valid', check)


def upgrade() -> None:
    _status_check(_AFTER)


def downgrade() -> None:
    # Closed work goes back to "working", the only status it can have had.
    op.execute("UPDATE assignments SET status = 'working' WHERE status = 'closed'")
    _status_check(_BEFORE)
