"""The drawn-ahead picture's points (issue 21): `map_pictures.points`, nullable.

A picture drawn on read needs every stored pose of the map version as arrays (maps/points.py):
at 1M poses reading them row by row is ~2.3 s of a cold first cut's ~2.8 s. The draw-ahead
that stores the default picture has just read them, so it stores them beside it, packed
(`points_bytes`, ~26 bytes a pose); a process that has not read that version (a restart,
another coordinator) loads them in ~0.05 s while the version matches. Rows stored before this
revision have none: those versions are read from the poses as before.

Revision ID: 0015
Revises: 0014
Create Date: 2026-12-09 12:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0015"
down_revision: str | None = "0014"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("map_pictures", sa.Column("points", sa.LargeBinary(), nullable=True))


def downgrade() -> None:
    op.execute("ALTER TABLE map_pictures DROP COLUMN points")
