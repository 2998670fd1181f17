"""The keeper's lease on an exploration: `explorations.manifolds_keeper` (the id of the
coordinator process that keeps the exploration's manifold table) and
`explorations.manifolds_keeper_until` (when its lease runs out), both nullable (null: no
process keeps it).

Revision ID: 0020_keeper_lease
Revises: 0019_success_draws
Create Date: 2026-12-11 00:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0020_keeper_lease"
down_revision: str | None = "0019_success_draws"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("explorations",
                  sa.Column("manifolds_keeper", sa.String(length=32), nullable=True))
    op.add_column("explorations",
                  sa.Column("manifolds_keeper_until", sa.DateTime(timezone=True), nullable=True))


def downgrade() -> None:
    op.execute("ALTER TABLE explorations DROP COLUMN manifolds_keeper_until")
    op.execute("ALTER TABLE explorations DROP COLUMN manifolds_keeper")
