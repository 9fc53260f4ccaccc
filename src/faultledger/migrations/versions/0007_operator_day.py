"""The operator's day and the episodes: acknowledgement, shelving, first occurrence ever.

Six columns on ``faults`` (docs/semantics.md, "The operator's day") and the statistics
table of acknowledgements and shelvings, ``stat_operator`` (docs/statistics.md). Their values are
folds of the log (FAILED reports per episode and in total, the first one ever, the first
confirmation of the episode), which no SQL over the old rows can recover. So the projections
and statistics are emptied with their checkpoints (the log's identity row stays): the open
that follows the upgrade finds them at seq 0 and replays the whole log into them, and an
upgraded database has the same faults and figures as a new one. No record is touched.

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


_PROJECTIONS = ("faults", "transitions", "stat_facts", "stat_episodes", "stat_minutes",
                "stat_hours", "stat_goals", "stat_codes")
"""Emptied for the replay; ``ledger_identity`` stays (the replay meets its record again)."""
_SEQ = sa.BigInteger().with_variant(sa.Integer(), "sqlite")


def upgrade() -> None:
    with op.batch_alter_table("faults") as batch:
        for column in _columns():
            batch.add_column(column)
    op.create_table(
        "stat_operator",
        sa.Column("seq", _SEQ, primary_key=True, autoincrement=False),
        sa.Column("kind", sa.String(8), nullable=False),
        sa.Column("fault_code", sa.String(128), nullable=False),
        sa.Column("source_id", sa.Text(), nullable=False),
        sa.Column("severity", sa.Integer(), nullable=False),
        sa.Column("at_ns", sa.BigInteger(), nullable=False),
        sa.Column("delay_ns", sa.BigInteger(), nullable=True),
        sa.Column("until_ns", sa.BigInteger(), nullable=True),
        sa.Column("end_seq", sa.BigInteger(), nullable=True),
        sa.Column("end_ns", sa.BigInteger(), nullable=True),
    )
    op.create_index("ix_stat_operator_at", "stat_operator", ["at_ns"])
    _empty_projections()


def downgrade() -> None:
    op.drop_index("ix_stat_operator_at", "stat_operator")
    op.drop_table("stat_operator")
    with op.batch_alter_table("faults") as batch:
        for column in reversed(_columns()):
            batch.drop_column(column.name)
    # The columns that stay are what an older version folds: nothing to recompute.


def _empty_projections() -> None:
    """Projections, not records: the next open replays the log into them."""
    for table in _PROJECTIONS:
        op.execute(f"DELETE FROM {table}")
    op.execute("DELETE FROM checkpoints WHERE name = 'projection'")
    op.execute("UPDATE checkpoints SET seq = 0 WHERE name = 'statistics'")  # as 0002-0006
