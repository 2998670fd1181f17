"""Tiles say which round of work planned them (`round`), instead of a level of 100 + k.

Local search round k used to be stored as tile level 100 + k, so that its tiles were leased
after every refinement tile. Now a tile has a `round` (0: the first pass and all that refines
it; k ≥ 1: the strategy's k-th later round, local search round k for the adaptive strategy)
and its true lattice level (the finest, for search tiles); tiles are leased by round, then
level, then id, which is the same order. The unique key and the queue-order index gain the
round. On SQLite the table is rebuilt (batch mode) keeping AUTOINCREMENT and every row, with
foreign-key enforcement off as in 0006.

Revision ID: 0007
Revises: 0006
Create Date: 2026-12-03 10:00:00
"""

from collections.abc import Sequence
from contextlib import contextmanager

import sqlalchemy as sa
from alembic import op

revision: str = "0007"
down_revision: str | None = "0006"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

SEARCH_LEVEL_BASE = 100  # the old encoding, only to convert it


@contextmanager
def _foreign_keys_off():
    bind = op.get_bind()
    if bind.dialect.name != "sqlite":
        yield
        return
    context = op.get_context()
    with context.autocommit_block():
        op.execute("PRAGMA foreign_keys=OFF")
    try:
        yield
        broken = bind.exec_driver_sql("PRAGMA foreign_key_check").fetchall()
        if broken:
            raise RuntimeError(f"foreign keys broken by the rebuild: {broken[:5]}")
    finally:
        with context.autocommit_block():
            op.execute("PRAGMA foreign_keys=ON")


def _batch():
    return op.batch_alter_table("tiles", table_kwargs={"sqlite_autoincrement": True})


def _refinement_levels() -> str:
    """SQL: the refinement depth of the tile's exploration, read from its stored spec."""
    if op.get_bind().dialect.name == "sqlite":
        levels = "json_extract(e.spec, '$.refinement.levels')"
    else:
        levels = "CAST(e.spec -> 'refinement' ->> 'levels' AS INTEGER)"
    return f"COALESCE((SELECT {levels} FROM explorations e WHERE e.id = tiles.exploration_id), 0)"


def upgrade() -> None:
    with _foreign_keys_off():
        with _batch() as batch_op:
            batch_op.add_column(sa.Column("round", sa.Integer(), server_default="0",
                                          nullable=False))
            batch_op.drop_constraint("uq_tiles_exploration_id_level_index", type_="unique")
            batch_op.drop_index("ix_tiles_queue_order")
        op.execute(
            f"UPDATE tiles SET round = level - {SEARCH_LEVEL_BASE - 1}, "
            f"level = {_refinement_levels()} WHERE level >= {SEARCH_LEVEL_BASE}"
        )
        with _batch() as batch_op:
            batch_op.create_unique_constraint(
                "uq_tiles_exploration_id_round_level_index",
                ["exploration_id", "round", "level", "index"])
            batch_op.create_index("ix_tiles_queue_order",
                                  ["state", "exploration_id", "round", "level", "id"])


def downgrade() -> None:
    with _foreign_keys_off():
        with _batch() as batch_op:
            batch_op.drop_constraint("uq_tiles_exploration_id_round_level_index", type_="unique")
            batch_op.drop_index("ix_tiles_queue_order")
        op.execute(
            f"UPDATE tiles SET level = round + {SEARCH_LEVEL_BASE - 1} WHERE round > 0"
        )
        with _batch() as batch_op:
            batch_op.drop_column("round")
            batch_op.create_unique_constraint(
                "uq_tiles_exploration_id_level_index", ["exploration_id", "level", "index"])
            batch_op.create_index("ix_tiles_queue_order",
                                  ["state", "exploration_id", "level", "id"])
