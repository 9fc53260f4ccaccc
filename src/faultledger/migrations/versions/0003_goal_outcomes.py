"""Goal outcome statistics: per-minute goal counts and the goal facts table.

Goal outcome records (kind ``goal_outcome``) need no change of the event log: they are
ordinary records with a NULL fault code. This revision adds what the statistics count them
with, and moves the statistics checkpoint back to seq 0 so the first open after the upgrade
recomputes every statistics table from the whole log (as after 0002): an upgraded database
has the same figures as a new one. No record is touched.

Revision ID: 0003_goal_outcomes
Revises: 0002_statistics
Create Date: 2026-11-24
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003_goal_outcomes"
down_revision: str | None = "0002_statistics"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_SEQ = sa.BigInteger().with_variant(sa.Integer(), "sqlite")
_GOAL_COLUMNS = ("aborted_goals", "canceled_goals", "succeeded_goals")


def upgrade() -> None:
    for name in _GOAL_COLUMNS:
        op.add_column("stat_minutes", sa.Column(name, sa.Integer(), nullable=False,
                                                server_default="0"))
    op.create_table(
        "stat_goals",
        sa.Column("seq", _SEQ, primary_key=True, autoincrement=False),
        sa.Column("at_ns", sa.BigInteger(), nullable=False),
        sa.Column("action", sa.String(256), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("server_node", sa.Text(), nullable=False),
    )
    op.create_index("ix_stat_goals_at", "stat_goals", ["at_ns"])
    op.create_index("ix_stat_goals_action_at", "stat_goals", ["action", "at_ns"])
    # A projection checkpoint, not a record: the next open recomputes the statistics.
    op.execute("UPDATE checkpoints SET seq = 0 WHERE name = 'statistics'")


def downgrade() -> None:
    op.drop_table("stat_goals")
    with op.batch_alter_table("stat_minutes") as batch:
        for name in _GOAL_COLUMNS:
            batch.drop_column(name)
    op.execute("UPDATE checkpoints SET seq = 0 WHERE name = 'statistics'")
