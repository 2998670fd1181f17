"""Stored map pictures (issue 21): `map_pictures`, one default PNG per exploration.

The default `map.png` of a finished map is rendered once, when its manifold table is refreshed
to final, and stored here (maps/stored.py), so that its first read in any coordinator process
is a row read (a cold render took 2.4 s at 10k poses and 36 s at 1M). A new table only.

Revision ID: 0014
Revises: 0012
Create Date: 2026-12-08 12:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0014"
down_revision: str | None = "0012"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "map_pictures",
        sa.Column("exploration_id", sa.Integer(), nullable=False),
        sa.Column("version", sa.String(length=200), nullable=False),
        sa.Column("png", sa.LargeBinary(), nullable=False),
        sa.Column("manifolds", sa.Integer(), nullable=False),
        sa.Column("poses", sa.Integer(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(["exploration_id"], ["explorations.id"],
                                name=op.f("fk_map_pictures_exploration_id_explorations"),
                                ondelete="CASCADE"),
        sa.PrimaryKeyConstraint("exploration_id", name=op.f("pk_map_pictures")),
    )


def downgrade() -> None:
    op.drop_table("map_pictures")
