"""Coordinator schema: objects, explorations, tiles, manifolds, poses, workers.

Revision ID: 0001
Revises: (none)
Create Date: 2026-11-26 04:56:01.932497
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op


revision: str = '0001'
down_revision: str | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table('objects',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('kind', sa.String(length=16), nullable=False),
    sa.Column('name', sa.String(length=255), nullable=False),
    sa.Column('content_hash', sa.String(length=64), nullable=True),
    sa.Column('mesh_format', sa.String(length=8), nullable=True),
    sa.Column('mesh', sa.LargeBinary(), nullable=True),
    sa.Column('properties', sa.JSON(), nullable=False),
    sa.Column('mesh_info', sa.JSON(), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_objects'))
    )
    with op.batch_alter_table('objects', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_objects_content_hash'), ['content_hash'], unique=False)

    op.create_table('workers',
    sa.Column('id', sa.String(length=128), nullable=False),
    sa.Column('host', sa.String(length=255), nullable=False),
    sa.Column('capacity', sa.Integer(), nullable=False),
    sa.Column('first_seen', sa.DateTime(timezone=True), nullable=False),
    sa.Column('last_seen', sa.DateTime(timezone=True), nullable=False),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_workers'))
    )
    op.create_table('explorations',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('object_id', sa.Integer(), nullable=False),
    sa.Column('spec', sa.JSON(), nullable=False),
    sa.Column('status', sa.String(length=16), nullable=False),
    sa.Column('tiles_total', sa.Integer(), nullable=False),
    sa.Column('poses_total', sa.Integer(), nullable=False),
    sa.Column('poses_done', sa.Integer(), nullable=False),
    sa.Column('viable_count', sa.Integer(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('updated_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('started_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('finished_at', sa.DateTime(timezone=True), nullable=True),
    sa.ForeignKeyConstraint(['object_id'], ['objects.id'], name=op.f('fk_explorations_object_id_objects')),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_explorations'))
    )
    with op.batch_alter_table('explorations', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_explorations_object_id'), ['object_id'], unique=False)
        batch_op.create_index(batch_op.f('ix_explorations_status'), ['status'], unique=False)

    op.create_table('manifolds',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('exploration_id', sa.Integer(), nullable=False),
    sa.Column('label', sa.Integer(), nullable=False),
    sa.Column('signature', sa.JSON(), nullable=True),
    sa.Column('size', sa.Integer(), nullable=False),
    sa.Column('best_pose_key', sa.String(length=128), nullable=True),
    sa.Column('best_mu_s', sa.Float(), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['exploration_id'], ['explorations.id'], name=op.f('fk_manifolds_exploration_id_explorations'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_manifolds')),
    sa.UniqueConstraint('exploration_id', 'label', name=op.f('uq_manifolds_exploration_id_label'))
    )
    op.create_table('tiles',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('exploration_id', sa.Integer(), nullable=False),
    sa.Column('level', sa.Integer(), nullable=False),
    sa.Column('index', sa.Integer(), nullable=False),
    sa.Column('cells', sa.JSON(), nullable=False),
    sa.Column('r_levels', sa.JSON(), nullable=False),
    sa.Column('attitudes', sa.JSON(), nullable=False),
    sa.Column('n_poses', sa.Integer(), nullable=False),
    sa.Column('state', sa.String(length=16), nullable=False),
    sa.Column('lease_owner', sa.String(length=128), nullable=True),
    sa.Column('lease_expires_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('lease_epoch', sa.Integer(), nullable=False),
    sa.Column('attempts', sa.Integer(), nullable=False),
    sa.Column('last_error', sa.Text(), nullable=True),
    sa.Column('updated_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('done_at', sa.DateTime(timezone=True), nullable=True),
    sa.ForeignKeyConstraint(['exploration_id'], ['explorations.id'], name=op.f('fk_tiles_exploration_id_explorations'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_tiles')),
    sa.UniqueConstraint('exploration_id', 'level', 'index', name=op.f('uq_tiles_exploration_id_level_index'))
    )
    with op.batch_alter_table('tiles', schema=None) as batch_op:
        batch_op.create_index('ix_tiles_exploration_id_state', ['exploration_id', 'state'], unique=False)
        batch_op.create_index('ix_tiles_state_lease_expires_at', ['state', 'lease_expires_at'], unique=False)

    op.create_table('poses',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('exploration_id', sa.Integer(), nullable=False),
    sa.Column('tile_id', sa.Integer(), nullable=True),
    sa.Column('pose_key', sa.String(length=128), nullable=False),
    sa.Column('theta', sa.Float(), nullable=False),
    sa.Column('phi', sa.Float(), nullable=False),
    sa.Column('r', sa.Float(), nullable=False),
    sa.Column('roll', sa.Float(), nullable=False),
    sa.Column('pitch', sa.Float(), nullable=False),
    sa.Column('yaw', sa.Float(), nullable=False),
    sa.Column('outcome', sa.String(length=16), nullable=False),
    sa.Column('viable', sa.Boolean(), nullable=False),
    sa.Column('mu_s', sa.Float(), nullable=False),
    sa.Column('effective_r', sa.Float(), nullable=True),
    sa.Column('effort_max_nm', sa.Float(), nullable=False),
    sa.Column('contacts_per_link', sa.JSON(), nullable=True),
    sa.Column('signature', sa.JSON(), nullable=True),
    sa.Column('grasp', sa.JSON(), nullable=True),
    sa.Column('manifold_id', sa.Integer(), nullable=True),
    sa.Column('worker_id', sa.String(length=128), nullable=True),
    sa.Column('eval_time_s', sa.Float(), nullable=False),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['exploration_id'], ['explorations.id'], name=op.f('fk_poses_exploration_id_explorations'), ondelete='CASCADE'),
    sa.ForeignKeyConstraint(['manifold_id'], ['manifolds.id'], name=op.f('fk_poses_manifold_id_manifolds'), ondelete='SET NULL'),
    sa.ForeignKeyConstraint(['tile_id'], ['tiles.id'], name=op.f('fk_poses_tile_id_tiles'), ondelete='SET NULL'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_poses')),
    sa.UniqueConstraint('exploration_id', 'pose_key', name=op.f('uq_poses_exploration_id_pose_key'))
    )
    with op.batch_alter_table('poses', schema=None) as batch_op:
        batch_op.create_index('ix_poses_exploration_id_created_at', ['exploration_id', 'created_at'], unique=False)
        batch_op.create_index('ix_poses_exploration_id_manifold_id', ['exploration_id', 'manifold_id'], unique=False)
        batch_op.create_index('ix_poses_exploration_id_viable', ['exploration_id', 'viable'], unique=False)



def downgrade() -> None:
    with op.batch_alter_table('poses', schema=None) as batch_op:
        batch_op.drop_index('ix_poses_exploration_id_viable')
        batch_op.drop_index('ix_poses_exploration_id_manifold_id')
        batch_op.drop_index('ix_poses_exploration_id_created_at')

    op.drop_table('poses')
    with op.batch_alter_table('tiles', schema=None) as batch_op:
        batch_op.drop_index('ix_tiles_state_lease_expires_at')
        batch_op.drop_index('ix_tiles_exploration_id_state')

    op.drop_table('tiles')
    op.drop_table('manifolds')
    with op.batch_alter_table('explorations', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_explorations_status'))
        batch_op.drop_index(batch_op.f('ix_explorations_object_id'))

    op.drop_table('explorations')
    op.drop_table('workers')
    with op.batch_alter_table('objects', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_objects_content_hash'))

    op.drop_table('objects')
