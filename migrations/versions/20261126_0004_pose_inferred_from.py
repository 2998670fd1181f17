"""Poses: the key of the pose whose outcome and μs a pose reuses (shortcut 2).

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-26 07:30:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0004"
down_revision: str | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("poses", schema=None) as batch_op:
        batch_op.add_column(sa.Column("inferred_from", sa.String(length=128), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("poses", schema=None) as batch_op:
        batch_op.drop_column("inferred_from")
