"""The log's indexes by time and by event_id move from ``events`` into tables of their own.

``ix_events_occurred_at`` and the UNIQUE constraint on ``events.event_id`` were two more
B-trees in every report's commit: a commit of one report wrote 3.5 pages into the WAL, of
one without them 1.2 (docs/performance.md, "Twelfth round"). ``events_by_time`` and
``events_by_id`` hold the same (key, seq) pairs, written with the projections as
``events_by_code`` is (store/log_index.py). The upgrade fills them from every record, in key
order, and drops the index and the constraint (on SQLite by copying ``events`` into a table
without it: the records, their seqs and hashes are copied as they are).

Revision ID: 0010_events_by_time_and_id
Revises: 0009_events_by_code
Create Date: 2026-11-29
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0010_events_by_time_and_id"
down_revision: str | None = "0009_events_by_code"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

UNIQUE_EVENT_ID = "events_event_id_key"
"""PostgreSQL's name for the unnamed UNIQUE (event_id) that 0001 created."""


def _events(unique_event_id: bool) -> sa.Table:
    """``events`` as 0001 made it, with or without its UNIQUE (event_id) (SQLite's copy)."""
    seq_type = sa.BigInteger().with_variant(sa.Integer(), "sqlite")
    return sa.Table(
        "events", sa.MetaData(),
        sa.Column("seq", seq_type, primary_key=True, autoincrement=False),
        sa.Column("event_id", sa.String(36), nullable=False, unique=unique_event_id),
        sa.Column("kind", sa.String(40), nullable=False),
        sa.Column("fault_code", sa.String(128), nullable=True),
        sa.Column("source_id", sa.Text(), nullable=True),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("occurred_at_ns", sa.BigInteger(), nullable=False),
        sa.Column("recorded_at_ns", sa.BigInteger(), nullable=False),
        sa.Column("schema_version", sa.Integer(), nullable=False),
        sa.Column("hash", sa.String(64), nullable=False),
    )


def upgrade() -> None:
    op.create_table(
        "events_by_time",
        sa.Column("occurred_at_ns", sa.BigInteger(), primary_key=True, autoincrement=False),
        sa.Column("seq", sa.BigInteger(), primary_key=True, autoincrement=False),
        sqlite_with_rowid=False,
    )
    op.create_table(
        "events_by_id",
        sa.Column("event_id", sa.String(36), primary_key=True),
        sa.Column("seq", sa.BigInteger(), nullable=False),
        sqlite_with_rowid=False,
    )
    op.execute("INSERT INTO events_by_time (occurred_at_ns, seq) SELECT occurred_at_ns, seq "
               "FROM events ORDER BY occurred_at_ns, seq")
    op.execute("INSERT INTO events_by_id (event_id, seq) SELECT event_id, seq "
               "FROM events ORDER BY event_id")
    op.drop_index("ix_events_occurred_at", "events")
    if op.get_bind().dialect.name == "sqlite":
        with op.batch_alter_table("events", copy_from=_events(False), recreate="always"):
            pass
    else:
        op.drop_constraint(UNIQUE_EVENT_ID, "events", type_="unique")


def downgrade() -> None:
    if op.get_bind().dialect.name == "sqlite":
        with op.batch_alter_table("events", copy_from=_events(True), recreate="always"):
            pass
    else:
        op.create_unique_constraint(UNIQUE_EVENT_ID, "events", ["event_id"])
    op.create_index("ix_events_occurred_at", "events", ["occurred_at_ns"])
    op.drop_table("events_by_id")
    op.drop_table("events_by_time")
