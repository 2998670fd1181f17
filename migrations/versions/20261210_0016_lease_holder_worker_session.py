"""Who may report a tile, and whose a worker id is: `tiles.lease_holder`,
`workers.session_hash`, both nullable.

`lease_holder` is the worker the tile's latest lease (epoch `lease_epoch`) went to; unlike
`lease_owner` it stays when the lease ends, so a late batch under that epoch is taken only
from that worker. Tiles leased before this revision get their current owner (none, where the
lease has ended: late batches of those leases are refused; their tiles are leased again).

`session_hash` is the SHA-256 of the session key of the worker process that registered the
id; a lease request or batch under the id with another key is refused. Rows of before this
revision get the key of the next request under their id.

Revision ID: 0016
Revises: 0015
Create Date: 2026-12-10 12:00:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0016"
down_revision: str | None = "0015"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("tiles", sa.Column("lease_holder", sa.String(length=128), nullable=True))
    op.execute("UPDATE tiles SET lease_holder = lease_owner WHERE lease_owner IS NOT NULL")
    op.add_column("workers", sa.Column("session_hash", sa.String(length=64), nullable=True))


def downgrade() -> None:
    op.execute("ALTER TABLE workers DROP COLUMN session_hash")
    op.execute("ALTER TABLE tiles DROP COLUMN lease_holder")
