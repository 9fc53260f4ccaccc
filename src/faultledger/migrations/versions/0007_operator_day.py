"""The operator's day and the episodes: acknowledgement, shelving, first occurrence ever.

Six columns on ``faults`` (docs/semantics.md, "The operator's day"). Their values are
folds of the log (FAILED reports per episode and in total, the first one ever, the first
confirmation of the episode), which no SQL over the old rows can recover. So the projections
and statistics are emptied with their checkpoints: the open that follows the upgrade finds
them at seq 0 and replays the whole log into them, and an upgraded database has the same
faults and figures as a new one. No record is touched.

Revision ID: 0007_operator_day
Revises: 0006_stat_hours
Create Date: 2026-11-26
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import sqlalchemy as sa
from alembic import op

revision: str = "0007_operator_day"
down_revision: str | None = "0006_stat_hours"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None



def _columns() -> tuple[sa.Column[Any], ...]:
    return (
        sa.Column("first_ever_ns", sa.BigInteger(), nullable=False, server_default="0"),
        sa.Column("episode_failures", sa.Integer(), nullable=False, server_default="0"),
        sa.Column("total_failures", sa.Integer(), nullable=False, server_default="0"),
        sa.Column("confirmed_ns", sa.BigInteger(), nullable=False, server_default="0"),
        sa.Column("acknowledged", sa.Text(), nullable=True),
        sa.Column("shelved", sa.Text(), nullable=True),
    )


_PROJECTIONS = ("faults", "transitions", "ledger_identity", "stat_facts", "stat_episodes",
                "stat_minutes", "stat_hours", "stat_goals", "stat_codes")


def upgrade() -> None:
    with op.batch_alter_table("faults") as batch:
        for column in _columns():
            batch.add_column(column)
    _empty_projections()


def downgrade() -> None:
    with op.batch_alter_table("faults") as batch:
        for column in reversed(_columns()):
            batch.drop_column(column.name)
    _empty_projections()


def _empty_projections() -> None:
    """Projections, not records: the next open replays the log into them."""
    for table in _PROJECTIONS:
        op.execute(f"DELETE FROM {table}")
    op.execute("DELETE FROM checkpoints WHERE name IN ('projection', 'statistics')")
