"""The manifold list without decoding summaries (issue 21): `manifolds.volume_cm3`.

`/manifolds` and `/manifolds/{label}` answer with the stored summaries' own JSON text, copied
into the response (api/manifolds.py); the dust line (the manifolds that are not large: how
many, their poses and volume) is read from columns: `size` and `large` were there, the volume
was only inside the summary. Existing rows get it from their summary. Plain ADD/DROP COLUMN.

Revision ID: 0012
Revises: 0011
Create Date: 2026-12-07 12:00:00
"""

import json
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0012"
down_revision: str | None = "0011"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("manifolds", sa.Column("volume_cm3", sa.Float(), nullable=True))
    bind = op.get_bind()
    rows = bind.execute(sa.text("SELECT id, CAST(summary AS TEXT) FROM manifolds "
                                "WHERE summary IS NOT NULL")).all()
    values = [{"i": i, "v": json.loads(text).get("volume_cm3")} for i, text in rows if text]
    if values:
        bind.execute(sa.text("UPDATE manifolds SET volume_cm3 = :v WHERE id = :i"), values)


def downgrade() -> None:
    op.execute("ALTER TABLE manifolds DROP COLUMN volume_cm3")
