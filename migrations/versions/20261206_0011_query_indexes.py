"""Indexes for the map routes' reads (issue 21): each answer is an index range, not a scan.

`/best` walks (exploration, viable, [label,] ranking value desc, μs desc, key) and stops at
`limit` (store/queries.py: per label, a pass over the poses with the value, then one over those
without, so a plain index serves both SQLite and PostgreSQL): by the robust ranking (the
default; overall and in one manifold), by the torque margin ratio (rank=point) and by μs.
Paged `/poses` is keyset on the row id: (exploration, id), and with its viable or manifold
filter the id is added to those two indexes, which it replaces (SQLite has the rowid in every
index; PostgreSQL needs it named).

Revision ID: 0011
Revises: 0010
Create Date: 2026-12-01 23:30:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0011"
down_revision: str | None = "0010"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# name → columns; "x DESC" is a descending key.
INDEXES: dict[str, list[str]] = {
    "ix_poses_exploration_id_id": ["exploration_id", "id"],
    "ix_poses_exploration_id_viable_id": ["exploration_id", "viable", "id"],
    "ix_poses_exploration_id_manifold_id_id": ["exploration_id", "manifold_id", "id"],
    "ix_poses_best_mu_s": ["exploration_id", "viable", "mu_s DESC", "pose_key"],
    "ix_poses_best_torque_margin_ratio": ["exploration_id", "viable", "torque_margin_ratio DESC",
                                          "mu_s DESC", "pose_key"],
    "ix_poses_best_robust": ["exploration_id", "viable", "robust_label", "robust_q DESC",
                             "mu_s DESC", "pose_key"],
    "ix_poses_manifold_best_robust": ["manifold_id", "viable", "robust_label", "robust_q DESC",
                                      "mu_s DESC", "pose_key"],
}
REPLACED: dict[str, list[str]] = {
    "ix_poses_exploration_id_viable": ["exploration_id", "viable"],
    "ix_poses_exploration_id_manifold_id": ["exploration_id", "manifold_id"],
}


def _columns(names: list[str]) -> list[sa.TextClause | str]:
    return [sa.text(n) if " " in n else n for n in names]


def upgrade() -> None:
    for name, columns in INDEXES.items():
        op.create_index(name, "poses", _columns(columns))
    for name in REPLACED:
        op.drop_index(name, table_name="poses")


def downgrade() -> None:
    for name, columns in REPLACED.items():
        op.create_index(name, "poses", _columns(columns))
    for name in INDEXES:
        op.drop_index(name, table_name="poses")
