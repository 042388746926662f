"""indexes for a DexYCB-sized project (40,000 tasks, 1,000 sequences)

A sequence's tasks (``tasks.sequence_id``) and a task's work, all of it or in one state
(``assignments (task_id, status)``), were found by scanning the whole table in every progress,
QC and solve read. The job listing of one status or kind, newest first, reads
``jobs (status, id)`` / ``jobs (kind, id)`` instead of sorting every match (they replace the
single-column indexes). Each worker's tally of QC outcomes is read from
``qc_reports (worker_id, outcome, provisional)`` alone (it replaces the index on worker_id).

Revision ID: 0012
Revises: 0011
Create Date: 2026-12-03 12:00:00
"""

from __future__ import annotations

from alembic import op

revision = '0012'
down_revision = '0011'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_index(op.f('ix_tasks_sequence_id'), 'tasks', ['sequence_id'], unique=False)
    op.create_index('ix_assignments_task_id_status', 'assignments', ['task_id', 'status'],
                    unique=False)
    op.create_index('ix_jobs_status_id', 'jobs', ['status', 'id'], unique=False)
    op.create_index('ix_jobs_kind_id', 'jobs', ['kind', 'id'], unique=False)
    op.drop_index(op.f('ix_jobs_status'), table_name='jobs')
    op.drop_index(op.f('ix_jobs_kind'), table_name='jobs')
    op.create_index('ix_qc_reports_worker_id_outcome', 'qc_reports',
                    ['worker_id', 'outcome', 'provisional'], unique=False)
    op.drop_index(op.f('ix_qc_reports_worker_id'), table_name='qc_reports')


def downgrade() -> None:
    op.create_index(op.f('ix_qc_reports_worker_id'), 'qc_reports', ['worker_id'], unique=False)
    op.drop_index('ix_qc_reports_worker_id_outcome', table_name='qc_reports')
    op.create_index(op.f('ix_jobs_kind'), 'jobs', ['kind'], unique=False)
    op.create_index(op.f('ix_jobs_status'), 'jobs', ['status'], unique=False)
    op.drop_index('ix_jobs_kind_id', table_name='jobs')
    op.drop_index('ix_jobs_status_id', table_name='jobs')
    op.drop_index('ix_assignments_task_id_status', table_name='assignments')
    op.drop_index(op.f('ix_tasks_sequence_id'), table_name='tasks')
