"""Statistics projections: facts, CONFIRMED episodes, per-minute sums, per-code fold state.

The tables start empty and are filled from the whole log by the first open after the upgrade
(the statistics checkpoint starts at seq 0), so an upgraded database has the same figures as
a new one.

Revision ID: 0002_statistics
Revises: 0001_initial
Create Date: 2026-11-23
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002_statistics"
down_revision: str | None = "0001_initial"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_SEQ = sa.BigInteger().with_variant(sa.Integer(), "sqlite")


def _counts(*names: str) -> list[sa.Column[int]]:
    return [sa.Column(name, sa.Integer(), nullable=False) for name in names]


def upgrade() -> None:
    op.create_table(
        "stat_facts",
        sa.Column("seq", _SEQ, primary_key=True, autoincrement=False),
        sa.Column("at_ns", sa.BigInteger(), nullable=False),
        sa.Column("fault_code", sa.String(128), nullable=False),
        sa.Column("source_id", sa.Text(), nullable=False),
        sa.Column("severity", sa.Integer(), nullable=False),
        *_counts("failed", "passed", "activation", "occurrence", "confirmation", "heal",
                 "clear", "chatter"),
    )
    op.create_index("ix_stat_facts_at", "stat_facts", ["at_ns"])
    op.create_index("ix_stat_facts_code_at", "stat_facts", ["fault_code", "at_ns"])
    op.create_index("ix_stat_facts_confirmation_at", "stat_facts", ["at_ns", "fault_code"],
                    sqlite_where=sa.text("confirmation = 1"),
                    postgresql_where=sa.text("confirmation = 1"))
    op.create_index("ix_stat_facts_chatter_at", "stat_facts", ["at_ns", "fault_code"],
                    sqlite_where=sa.text("chatter = 1"), postgresql_where=sa.text("chatter = 1"))

    op.create_table(
        "stat_episodes",
        sa.Column("start_seq", _SEQ, primary_key=True, autoincrement=False),
        sa.Column("fault_code", sa.String(128), nullable=False),
        sa.Column("source_id", sa.Text(), nullable=False),
        sa.Column("severity", sa.Integer(), nullable=False),
        sa.Column("start_ns", sa.BigInteger(), nullable=False),
        sa.Column("end_seq", sa.BigInteger(), nullable=True),
        sa.Column("end_ns", sa.BigInteger(), nullable=True),
    )
    op.create_index("ix_stat_episodes_code_start", "stat_episodes", ["fault_code", "start_ns"])
    op.create_index("ix_stat_episodes_start", "stat_episodes", ["start_ns"])
    op.create_index("ix_stat_episodes_end", "stat_episodes", ["end_ns"])
    long = sa.text("end_ns - start_ns >= 86400000000000")  # stale: CONFIRMED for 24 h or more
    op.create_index("ix_stat_episodes_long_end", "stat_episodes", ["end_ns"],
                    sqlite_where=long, postgresql_where=long)

    op.create_table(
        "stat_minutes",
        sa.Column("minute", sa.BigInteger(), primary_key=True, autoincrement=False),
        *_counts("failed", "passed", "activation", "occurrence", "confirmation", "heal",
                 "clear", "starts"),
        sa.Column("start_offset_ns", sa.BigInteger(), nullable=False),
        sa.Column("ends", sa.Integer(), nullable=False),
        sa.Column("end_offset_ns", sa.BigInteger(), nullable=False),
        sa.Column("repairs", sa.Integer(), nullable=False),
        sa.Column("repair_ns", sa.BigInteger(), nullable=False),
    )

    op.create_table(
        "stat_codes",
        sa.Column("fault_code", sa.String(128), primary_key=True),
        sa.Column("last_failed", sa.Boolean(), nullable=False),
        sa.Column("activations", sa.Text(), nullable=False),
        sa.Column("episode_start_seq", sa.BigInteger(), nullable=True),
    )


def downgrade() -> None:
    for table in ("stat_codes", "stat_minutes", "stat_episodes", "stat_facts"):
        op.drop_table(table)
