"""Explorations note when their manifolds were last computed, instead of every manifold row.

Each manifold's summary carried `final` and `poses_done` of the refresh that wrote it; the
exploration row now holds them once (`manifolds_poses_done`, `manifolds_final`). Existing
explorations start with none noted (NULL, false): the first read of their manifolds computes
them once more, from the same stored poses, to the same map. The keys left in old summaries
are ignored. Plain ADD/DROP COLUMN, which SQLite (3.35+) does in place, so the explorations
table keeps AUTOINCREMENT without a rebuild.

Revision ID: 0008
Revises: 0007
Create Date: 2026-12-04 10:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0008"
down_revision: str | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("explorations", sa.Column("manifolds_poses_done", sa.Integer(), nullable=True))
    op.add_column("explorations", sa.Column("manifolds_final", sa.Boolean(), nullable=False,
                                            server_default=sa.false()))


def downgrade() -> None:
    for name in ("manifolds_final", "manifolds_poses_done"):
        op.execute(f"ALTER TABLE explorations DROP COLUMN {name}")
