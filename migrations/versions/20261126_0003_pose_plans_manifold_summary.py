"""Adaptive exploration: planned poses (refinement dedupe) and manifold summaries.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-26 05:25:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "pose_plans",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("exploration_id", sa.Integer(), nullable=False),
        sa.Column("pose_key", sa.String(length=128), nullable=False),
        sa.Column("level", sa.Integer(), nullable=False),
        sa.Column("reason", sa.String(length=16), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["exploration_id"],
            ["explorations.id"],
            name=op.f("fk_pose_plans_exploration_id_explorations"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_pose_plans")),
        sa.UniqueConstraint(
            "exploration_id", "pose_key", name=op.f("uq_pose_plans_exploration_id_pose_key")
        ),
    )
    with op.batch_alter_table("manifolds", schema=None) as batch_op:
        batch_op.add_column(sa.Column("summary", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("manifolds", schema=None) as batch_op:
        batch_op.drop_column("summary")
    op.drop_table("pose_plans")
