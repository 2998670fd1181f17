"""Explorations on a table: `support_group` (the id of the first exploration of the group an
object on a plane was submitted as, one exploration per resting pose), `resting_index` and
`resting_probability` (the resting pose, itself in the spec's `support.resting`), all
nullable: a free-object exploration has none.

Revision ID: 0017_support
Revises: 0016
Create Date: 2026-12-06 00:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0017_support"
down_revision: str | None = "0016"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("explorations", sa.Column("support_group", sa.Integer(), nullable=True))
    op.add_column("explorations", sa.Column("resting_index", sa.Integer(), nullable=True))
    op.add_column("explorations", sa.Column("resting_probability", sa.Float(), nullable=True))
    op.create_index("ix_explorations_support_group", "explorations", ["support_group"])


def downgrade() -> None:
    op.drop_index("ix_explorations_support_group", table_name="explorations")
    op.execute("ALTER TABLE explorations DROP COLUMN resting_probability")
    op.execute("ALTER TABLE explorations DROP COLUMN resting_index")
    op.execute("ALTER TABLE explorations DROP COLUMN support_group")
