"""captures and admins

Revision ID: 0001
Revises: (none)
Create Date: 2026-11-23 11:08:32.525327
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0001'
down_revision = None
branch_labels = None
depends_on = None

def upgrade() -> None:
    op.create_table('admins',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('email', sa.String(length=320), nullable=False),
    sa.Column('password_hash', sa.String(length=300), nullable=False),
    sa.Column('active', sa.Boolean(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_admins')),
    sa.UniqueConstraint('email', name=op.f('uq_admins_email'))
    )
    op.create_table('subjects',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=200), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_subjects')),
    sa.UniqueConstraint('name', name=op.f('uq_subjects_name'))
    )
    op.create_table('sequences',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('subject_id', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=200), nullable=False),
    sa.Column('storage_uid', sa.String(length=64), nullable=False),
    sa.Column('num_frames', sa.Integer(), nullable=False),
    sa.Column('fps', sa.Float(), nullable=False),
    sa.Column('master_serial', sa.String(length=64), nullable=True),
    sa.Column('source_kind', sa.String(length=16), nullable=False),
    sa.Column('fingerprint', sa.String(length=64), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.CheckConstraint('num_frames > 0', name=op.f('ck_sequences_num_frames_positive')),
    sa.ForeignKeyConstraint(['subject_id'], ['subjects.id'], name=op.f('fk_sequences_subject_id_subjects'), ondelete='RESTRICT'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_sequences')),
    sa.UniqueConstraint('storage_uid', name=op.f('uq_sequences_storage_uid')),
    sa.UniqueConstraint('subject_id', 'name', name=op.f('uq_sequences_subject_id_name'))
    )
    op.create_table('cameras',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('sequence_id', sa.Integer(), nullable=False),
    sa.Column('serial', sa.String(length=64), nullable=False),
    sa.Column('view_index', sa.Integer(), nullable=False),
    sa.Column('width', sa.Integer(), nullable=False),
    sa.Column('height', sa.Integer(), nullable=False),
    sa.Column('fx', sa.Float(), nullable=False),
    sa.Column('fy', sa.Float(), nullable=False),
    sa.Column('ppx', sa.Float(), nullable=False),
    sa.Column('ppy', sa.Float(), nullable=False),
    sa.Column('distortion', sa.JSON(), nullable=False),
    sa.Column('extrinsics', sa.JSON(), nullable=False),
    sa.Column('has_depth', sa.Boolean(), nullable=False),
    sa.CheckConstraint('fx > 0 AND fy > 0', name=op.f('ck_cameras_focal_positive')),
    sa.CheckConstraint('width > 0 AND height > 0', name=op.f('ck_cameras_image_size_positive')),
    sa.ForeignKeyConstraint(['sequence_id'], ['sequences.id'], name=op.f('fk_cameras_sequence_id_sequences'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_cameras')),
    sa.UniqueConstraint('sequence_id', 'serial', name=op.f('uq_cameras_sequence_id_serial'))
    )
    op.create_table('hands',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('sequence_id', sa.Integer(), nullable=False),
    sa.Column('index', sa.Integer(), nullable=False),
    sa.Column('side', sa.String(length=8), nullable=False),
    sa.Column('calib_name', sa.String(length=200), nullable=True),
    sa.Column('betas', sa.JSON(), nullable=True),
    sa.CheckConstraint("side IN ('right', 'left')", name=op.f('ck_hands_side_valid')),
    sa.ForeignKeyConstraint(['sequence_id'], ['sequences.id'], name=op.f('fk_hands_sequence_id_sequences'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_hands')),
    sa.UniqueConstraint('sequence_id', 'index', name=op.f('uq_hands_sequence_id_index'))
    )
    op.create_table('scene_objects',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('sequence_id', sa.Integer(), nullable=False),
    sa.Column('index', sa.Integer(), nullable=False),
    sa.Column('ycb_id', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=200), nullable=False),
    sa.Column('mesh_key', sa.String(length=500), nullable=False),
    sa.Column('num_vertices', sa.Integer(), nullable=False),
    sa.Column('num_faces', sa.Integer(), nullable=False),
    sa.Column('grasped', sa.Boolean(), nullable=False),
    sa.Column('initial_pose', sa.JSON(), nullable=True),
    sa.ForeignKeyConstraint(['sequence_id'], ['sequences.id'], name=op.f('fk_scene_objects_sequence_id_sequences'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_scene_objects')),
    sa.UniqueConstraint('sequence_id', 'index', name=op.f('uq_scene_objects_sequence_id_index'))
    )
    op.create_table('frames',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('camera_id', sa.Integer(), nullable=False),
    sa.Column('index', sa.Integer(), nullable=False),
    sa.Column('color_key', sa.String(length=500), nullable=False),
    sa.Column('color_bytes', sa.Integer(), nullable=False),
    sa.Column('depth_key', sa.String(length=500), nullable=True),
    sa.Column('thumb_key', sa.String(length=500), nullable=True),
    sa.Column('stats', sa.JSON(), nullable=True),
    sa.CheckConstraint('"index" >= 0', name=op.f('ck_frames_index_nonnegative')),
    sa.ForeignKeyConstraint(['camera_id'], ['cameras.id'], name=op.f('fk_frames_camera_id_cameras'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_frames')),
    sa.UniqueConstraint('camera_id', 'index', name=op.f('uq_frames_camera_id_index'))
    )

def downgrade() -> None:
    op.drop_table('frames')
    op.drop_table('scene_objects')
    op.drop_table('hands')
    op.drop_table('cameras')
    op.drop_table('sequences')
    op.drop_table('subjects')
    op.drop_table('admins')
