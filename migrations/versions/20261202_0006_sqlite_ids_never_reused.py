"""SQLite: exploration and tile ids are never handed out again after a DELETE (AUTOINCREMENT).

Without AUTOINCREMENT, SQLite gives a new row the largest id in use + 1, so deleting the
newest exploration let the next one take its id, and its tiles the ids of the deleted tiles: a
late result batch for a deleted tile (its id travels on the wire) could then land on a tile
of another exploration. PostgreSQL's sequences never hand out an id twice: nothing to do
there.

SQLite cannot add AUTOINCREMENT to a table in place, so both tables are rebuilt (batch
mode, rows and ids kept). Foreign-key enforcement is off while they are: with it on, dropping
the old `explorations` would first delete, by ON DELETE CASCADE, every tile, pose, manifold
and plan that refers to it. The pragma only takes effect outside a transaction, hence the
autocommit blocks; `PRAGMA foreign_key_check` must find nothing before it goes back on.

Revision ID: 0006
Revises: 0005
Create Date: 2026-12-02 10:00:00
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0006"
down_revision: str | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLES = ("explorations", "tiles")


def _rebuild(autoincrement: bool) -> None:
    bind = op.get_bind()
    if bind.dialect.name != "sqlite":
        return
    context = op.get_context()
    with context.autocommit_block():
        op.execute("PRAGMA foreign_keys=OFF")
    try:
        for table in TABLES:
            with op.batch_alter_table(
                table, recreate="always", table_kwargs={"sqlite_autoincrement": autoincrement}
            ):
                pass
        broken = bind.exec_driver_sql("PRAGMA foreign_key_check").fetchall()
        if broken:
            raise RuntimeError(f"foreign keys broken by the rebuild: {broken[:5]}")
    finally:
        with context.autocommit_block():
            op.execute("PRAGMA foreign_keys=ON")


def upgrade() -> None:
    _rebuild(autoincrement=True)


def downgrade() -> None:
    _rebuild(autoincrement=False)
