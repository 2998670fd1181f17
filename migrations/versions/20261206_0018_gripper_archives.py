"""Grippers that travel to workers: `grippers` (a gripper's archive by its content hash) and
`explorations.gripper_hash` (null: a shipped gripper, which every worker has).

Explorations of before this revision keep a null hash: their workers resolve the spec's
gripper themselves, as they did.

Revision ID: 0018_gripper_archives
Revises: 0017_support
Create Date: 2026-12-06 00:30:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0018_gripper_archives"
down_revision: str | None = "0017_support"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "grippers",
        sa.Column("content_hash", sa.String(length=64), primary_key=True),
        sa.Column("kind", sa.String(length=8), nullable=False),
        sa.Column("name", sa.String(length=255), nullable=False),
        sa.Column("archive", sa.LargeBinary(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    )
    op.add_column("explorations",
                  sa.Column("gripper_hash", sa.String(length=64), nullable=True))


def downgrade() -> None:
    op.execute("ALTER TABLE explorations DROP COLUMN gripper_hash")
    op.drop_table("grippers")
