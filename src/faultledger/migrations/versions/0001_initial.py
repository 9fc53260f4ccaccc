"""Initial schema: the event log, the fault and transition projections, checkpoints.

Revision ID: 0001_initial
Revises:
Create Date: 2026-11-22
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0001_initial"
down_revision: str | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_SEQ = sa.BigInteger().with_variant(sa.Integer(), "sqlite")


def upgrade() -> None:
    op.create_table(
        "events",
        sa.Column("seq", _SEQ, primary_key=True, autoincrement=False),
        sa.Column("event_id", sa.String(36), nullable=False, unique=True),
        sa.Column("kind", sa.String(40), nullable=False),
        sa.Column("fault_code", sa.String(128), nullable=True),
        sa.Column("source_id", sa.Text(), nullable=True),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("occurred_at_ns", sa.BigInteger(), nullable=False),
        sa.Column("recorded_at_ns", sa.BigInteger(), nullable=False),
        sa.Column("schema_version", sa.Integer(), nullable=False),
        sa.Column("hash", sa.String(64), nullable=False),
    )
    op.create_index("ix_events_fault_code_seq", "events", ["fault_code", "seq"])
    op.create_index("ix_events_occurred_at", "events", ["occurred_at_ns"])

    op.create_table(
        "faults",
        sa.Column("fault_code", sa.String(128), primary_key=True),
        sa.Column("severity", sa.Integer(), nullable=False),
        sa.Column("description", sa.Text(), nullable=False),
        sa.Column("first_occurred_ns", sa.BigInteger(), nullable=False),
        sa.Column("last_occurred_ns", sa.BigInteger(), nullable=False),
        sa.Column("last_passed_ns", sa.BigInteger(), nullable=False),
        sa.Column("occurrence_count", sa.Integer(), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("reporting_sources", sa.Text(), nullable=False),
        sa.Column("debounce_counter", sa.Integer(), nullable=False),
        sa.Column("last_report_failed", sa.Boolean(), nullable=False),
    )

    op.create_table(
        "transitions",
        sa.Column("seq", _SEQ, primary_key=True, autoincrement=False),
        sa.Column("fault_code", sa.String(128), nullable=False),
        sa.Column("from_status", sa.String(16), nullable=True),
        sa.Column("to_status", sa.String(16), nullable=False),
        sa.Column("at_ns", sa.BigInteger(), nullable=False),
        sa.Column("cause", sa.String(16), nullable=False),
        sa.Column("source_id", sa.Text(), nullable=False),
    )
    op.create_index("ix_transitions_fault_code_seq", "transitions", ["fault_code", "seq"])
    op.create_index("ix_transitions_at", "transitions", ["at_ns"])

    op.create_table(
        "checkpoints",
        sa.Column("name", sa.String(40), primary_key=True),
        sa.Column("seq", sa.BigInteger(), nullable=False),
        sa.Column("hash", sa.String(64), nullable=False),
        sa.Column("policy_seq", sa.BigInteger(), nullable=False),
    )


def downgrade() -> None:
    op.drop_table("checkpoints")
    op.drop_table("transitions")
    op.drop_table("faults")
    op.drop_table("events")
