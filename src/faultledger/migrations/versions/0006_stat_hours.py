"""Statistics per hour, and two partial indexes for the statistics reads.

``stat_hours`` holds the sums ``stat_minutes`` holds, per hour: a question over whole hours
(shifts, days) reads 60 times fewer rows (a fleet central answers "per shift per robot" over
a hundred robots). The minutes with confirmations (the flood windows) and the activations
(the e-stops) get partial indexes. Like 0002 and 0003, the statistics checkpoint moves back
to seq 0, so the first open after the upgrade recomputes every statistics table from the
whole log: an upgraded database has the same figures as a new one. No record is touched.

Revision ID: 0006_stat_hours
Revises: 0005_fleet
Create Date: 2026-11-26
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006_stat_hours"
down_revision: str | None = "0005_fleet"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_COUNTS = ("failed", "passed", "activation", "occurrence", "confirmation", "heal", "clear",
           "starts")


def upgrade() -> None:
    op.create_table(
        "stat_hours",
        sa.Column("hour", sa.BigInteger(), primary_key=True, autoincrement=False),
        *(sa.Column(name, sa.Integer(), nullable=False) for name in _COUNTS),
        sa.Column("start_offset_ns", sa.BigInteger(), nullable=False),
        sa.Column("ends", sa.Integer(), nullable=False),
        sa.Column("end_offset_ns", sa.BigInteger(), nullable=False),
        sa.Column("repairs", sa.Integer(), nullable=False),
        sa.Column("repair_ns", sa.BigInteger(), nullable=False),
        sa.Column("aborted_goals", sa.Integer(), nullable=False, server_default="0"),
        sa.Column("canceled_goals", sa.Integer(), nullable=False, server_default="0"),
        sa.Column("succeeded_goals", sa.Integer(), nullable=False, server_default="0"),
    )
    confirmed = sa.text("confirmation > 0")
    op.create_index("ix_stat_minutes_confirmation", "stat_minutes", ["minute", "confirmation"],
                    sqlite_where=confirmed, postgresql_where=confirmed)
    activated = sa.text("activation = 1")
    op.create_index("ix_stat_facts_activation", "stat_facts", ["fault_code", "at_ns"],
                    sqlite_where=activated, postgresql_where=activated)
    # A projection checkpoint, not a record: the next open recomputes the statistics.
    op.execute("UPDATE checkpoints SET seq = 0 WHERE name = 'statistics'")


def downgrade() -> None:
    op.drop_index("ix_stat_facts_activation", "stat_facts")
    op.drop_index("ix_stat_minutes_confirmation", "stat_minutes")
    op.drop_table("stat_hours")
    op.execute("UPDATE checkpoints SET seq = 0 WHERE name = 'statistics'")
