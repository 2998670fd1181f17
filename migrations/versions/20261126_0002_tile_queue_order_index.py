"""Index for the lease order of queued tiles (state, exploration, level, id).

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-26 05:08:16.861721
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op


revision: str = '0002'
down_revision: str | None = '0001'
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table('tiles', schema=None) as batch_op:
        batch_op.create_index('ix_tiles_queue_order', ['state', 'exploration_id', 'level', 'id'], unique=False)



def downgrade() -> None:
    with op.batch_alter_table('tiles', schema=None) as batch_op:
        batch_op.drop_index('ix_tiles_queue_order')

