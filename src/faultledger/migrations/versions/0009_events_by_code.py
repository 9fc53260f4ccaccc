"""The log's index by fault code moves from ``events`` into ``events_by_code``.

``ix_events_fault_code_seq`` put each report into the leaf page of its code: a group commit
of eight reports over eight codes wrote eight more WAL pages, and on a large log read them
back first. ``events_by_code`` holds the same (fault_code, seq) pairs, written with the
projections (store/code_index.py). The upgrade fills it from every record with a code, in
key order, and drops the index; no record is touched.

Revision ID: 0009_events_by_code
Revises: 0008_alerts
Create Date: 2026-11-29
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0009_events_by_code"
down_revision: str | None = "0008_alerts"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "events_by_code",
        sa.Column("fault_code", sa.String(128), primary_key=True),
        sa.Column("seq", sa.BigInteger(), primary_key=True, autoincrement=False),
        sqlite_with_rowid=False,
    )
    op.execute("INSERT INTO events_by_code (fault_code, seq) SELECT fault_code, seq "
               "FROM events WHERE fault_code IS NOT NULL ORDER BY fault_code, seq")
    op.drop_index("ix_events_fault_code_seq", "events")


def downgrade() -> None:
    op.create_index("ix_events_fault_code_seq", "events", ["fault_code", "seq"])
    op.drop_table("events_by_code")
