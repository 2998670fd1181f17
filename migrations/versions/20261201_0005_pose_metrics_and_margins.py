"""Poses: static grasp metrics (μg, μf, μm) and robustness margins and grasp tests.

Revision ID: 0005
Revises: 0004
Create Date: 2026-12-01 16:30:00
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# NULL where the worker did not compute the value (not chosen, or the pose was not held).
COLUMNS = (
    "mu_g",
    "mu_f",
    "mu_m",
    "torque_margin_nm",
    "torque_margin_ratio",
    "friction_margin",
    "gravity_test_share",
    "force_test_share",
    "tug_force_n",
    "shake_survival_s",
)


def upgrade() -> None:
    with op.batch_alter_table("poses", schema=None) as batch_op:
        for name in COLUMNS:
            batch_op.add_column(sa.Column(name, sa.Float(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("poses", schema=None) as batch_op:
        for name in reversed(COLUMNS):
            batch_op.drop_column(name)
