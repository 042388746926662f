"""tasks assignments tracks

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-23 11:36:13.259024
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0002'
down_revision = '0001'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table('tasks',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('sequence_id', sa.Integer(), nullable=False),
    sa.Column('camera_id', sa.Integer(), nullable=False),
    sa.Column('kind', sa.String(length=8), nullable=False),
    sa.Column('target_key', sa.String(length=32), nullable=False),
    sa.Column('hand_id', sa.Integer(), nullable=True),
    sa.Column('object_id', sa.Integer(), nullable=True),
    sa.Column('num_points', sa.Integer(), nullable=False),
    sa.Column('highlight', sa.JSON(), nullable=True),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint("kind IN ('hand', 'object')", name=op.f('ck_tasks_kind_valid')),
    sa.CheckConstraint('num_points > 0', name=op.f('ck_tasks_num_points_positive')),
    sa.ForeignKeyConstraint(['camera_id'], ['cameras.id'], name=op.f('fk_tasks_camera_id_cameras'), ondelete='CASCADE'),
    sa.ForeignKeyConstraint(['hand_id'], ['hands.id'], name=op.f('fk_tasks_hand_id_hands'), ondelete='CASCADE'),
    sa.ForeignKeyConstraint(['object_id'], ['scene_objects.id'], name=op.f('fk_tasks_object_id_scene_objects'), ondelete='CASCADE'),
    sa.ForeignKeyConstraint(['sequence_id'], ['sequences.id'], name=op.f('fk_tasks_sequence_id_sequences'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_tasks')),
    sa.UniqueConstraint('camera_id', 'target_key', name=op.f('uq_tasks_camera_id_target_key'))
    )
    op.create_table('assignments',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('task_id', sa.Integer(), nullable=False),
    sa.Column('worker_id', sa.String(length=64), nullable=False),
    sa.Column('external_id', sa.String(length=64), nullable=False),
    sa.Column('hit_id', sa.String(length=64), nullable=True),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('version', sa.Integer(), nullable=False),
    sa.Column('edit_count', sa.Integer(), nullable=False),
    sa.Column('working_time_s', sa.Float(), nullable=False),
    sa.Column('saved_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('submitted_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint("status IN ('working', 'submitted', 'approved', 'rejected')", name=op.f('ck_assignments_status_valid')),
    sa.CheckConstraint('version >= 0', name=op.f('ck_assignments_version_nonnegative')),
    sa.ForeignKeyConstraint(['task_id'], ['tasks.id'], name=op.f('fk_assignments_task_id_tasks'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_assignments')),
    sa.UniqueConstraint('external_id', name=op.f('uq_assignments_external_id'))
    )
    op.create_table('tracks',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('assignment_id', sa.Integer(), nullable=False),
    sa.Column('point_index', sa.Integer(), nullable=False),
    sa.Column('keyframes', sa.JSON(), nullable=False),
    sa.ForeignKeyConstraint(['assignment_id'], ['assignments.id'], name=op.f('fk_tracks_assignment_id_assignments'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_tracks')),
    sa.UniqueConstraint('assignment_id', 'point_index', name=op.f('uq_tracks_assignment_id_point_index'))
    )


def downgrade() -> None:
    op.drop_table('tracks')
    op.drop_table('assignments')
    op.drop_table('tasks')
