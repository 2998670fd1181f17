"""Poses whose evaluation raised are stored with outcome `error` and the exception's message.

A worker isolates a pose that raises instead of failing its tile (workers/runtime/isolation.py),
so the message travels with the pose (`PoseResult.error`) and is kept in `poses.error`; NULL
for every other pose. Plain ADD/DROP COLUMN (in place on SQLite 3.35+).

Revision ID: 0009
Revises: 0008
Create Date: 2026-12-05 10:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0009"
down_revision: str | None = "0008"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("poses", sa.Column("error", sa.String(length=2000), nullable=True))


def downgrade() -> None:
    op.execute("ALTER TABLE poses DROP COLUMN error")
