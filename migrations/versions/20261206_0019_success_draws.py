"""The draws of a success probability as their own work: `tiles.sample`,
`tiles.needs_engines` and `poses.sample`, all nullable.

`tiles.sample` holds what a tile of draws asks beyond its poses: the engines each draw runs
in and each pose's friction, mass and closing-effort scales; its poses are evaluated outcome
only. `tiles.needs_engines` is those engines, sorted and comma-joined, so a lease reads
whether a worker runs them all without decoding JSON. `poses.sample` is a draw's record: its
scales, its outcome and links in contact in each engine, and which fields it leaves out.
NULL everywhere else.

Revision ID: 0019_success_draws
Revises: 0018_gripper_archives
Create Date: 2026-12-06 00:30:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0019_success_draws"
down_revision: str | None = "0018_gripper_archives"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("tiles", sa.Column("sample", sa.JSON(), nullable=True))
    op.add_column("tiles", sa.Column("needs_engines", sa.String(length=64), nullable=True))
    op.add_column("poses", sa.Column("sample", sa.JSON(), nullable=True))


def downgrade() -> None:
    op.execute("ALTER TABLE poses DROP COLUMN sample")
    op.execute("ALTER TABLE tiles DROP COLUMN needs_engines")
    op.execute("ALTER TABLE tiles DROP COLUMN sample")
