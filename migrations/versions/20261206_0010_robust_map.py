"""The robust map (issue 18): robust success, quality and label per pose, certification links,
and per manifold the core volume, the robust best grasp and whether it is large.

poses: `robust_s`, `robust_q`, `robust_label` (kept current with the manifolds,
manifolds/robust.py) and `certifies` (the key of the pose whose certification an evaluation
serves), all NULL-able, with a partial index on (exploration_id, certifies) over the rows that
have one. manifolds: `core_volume_cm3`, `robust_best_key`, `robust_best_q` and `large` (false
for existing rows). Existing explorations get their manifolds' refresh mark cleared, so the
next read recomputes them (as 0008 did) and fills the new columns from the same poses.
Plain ADD/DROP COLUMN (in place on SQLite 3.35+).

Revision ID: 0010
Revises: 0009
Create Date: 2026-12-06 10:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0010"
down_revision: str | None = "0009"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_POSE_COLUMNS = ("robust_s", "robust_q", "robust_label", "certifies")
_MANIFOLD_COLUMNS = ("core_volume_cm3", "robust_best_key", "robust_best_q", "large")
_WHERE = sa.text("certifies IS NOT NULL")


def upgrade() -> None:
    op.add_column("poses", sa.Column("robust_s", sa.Float(), nullable=True))
    op.add_column("poses", sa.Column("robust_q", sa.Float(), nullable=True))
    op.add_column("poses", sa.Column("robust_label", sa.String(length=16), nullable=True))
    op.add_column("poses", sa.Column("certifies", sa.String(length=128), nullable=True))
    op.create_index("ix_poses_exploration_id_certifies", "poses",
                    ["exploration_id", "certifies"], sqlite_where=_WHERE,
                    postgresql_where=_WHERE)
    op.add_column("manifolds", sa.Column("core_volume_cm3", sa.Float(), nullable=True))
    op.add_column("manifolds", sa.Column("robust_best_key", sa.String(length=128),
                                         nullable=True))
    op.add_column("manifolds", sa.Column("robust_best_q", sa.Float(), nullable=True))
    op.add_column("manifolds", sa.Column("large", sa.Boolean(), nullable=False,
                                         server_default=sa.false()))
    op.execute("UPDATE explorations SET manifolds_poses_done = NULL")


def downgrade() -> None:
    op.drop_index("ix_poses_exploration_id_certifies", table_name="poses")
    for name in _POSE_COLUMNS:
        op.execute(f"ALTER TABLE poses DROP COLUMN {name}")
    for name in _MANIFOLD_COLUMNS:
        op.execute(f"ALTER TABLE manifolds DROP COLUMN {name}")
