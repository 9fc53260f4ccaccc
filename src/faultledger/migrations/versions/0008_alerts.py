"""Alert delivery: the outbox, a cursor and a lease per rule, a rule's marks.

docs/alerts.md. New tables only; no record or projection is touched.

Revision ID: 0008_alerts
Revises: 0007_operator_day
Create Date: 2026-11-28
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0008_alerts"
down_revision: str | None = "0007_operator_day"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_ID = sa.BigInteger().with_variant(sa.Integer(), "sqlite")


def upgrade() -> None:
    op.create_table(
        "alert_cursors",
        sa.Column("rule", sa.String(64), primary_key=True),
        sa.Column("seq", sa.BigInteger(), nullable=False),
        sa.Column("holder", sa.String(160), nullable=True),
        sa.Column("lease_until_ns", sa.BigInteger(), nullable=False),
    )
    op.create_table(
        "alert_outbox",
        sa.Column("id", _ID, primary_key=True, autoincrement=True),
        sa.Column("rule", sa.String(64), nullable=False),
        sa.Column("key", sa.String(255), nullable=False, unique=True),
        sa.Column("seq", sa.BigInteger(), nullable=False),
        sa.Column("event", sa.String(32), nullable=False),
        sa.Column("fault_code", sa.String(128), nullable=True),
        sa.Column("record_ns", sa.BigInteger(), nullable=False),
        sa.Column("payload", sa.Text(), nullable=False),
        sa.Column("state", sa.String(16), nullable=False),
        sa.Column("attempts", sa.Integer(), nullable=False),
        sa.Column("last_error", sa.Text(), nullable=True),
        sa.Column("next_attempt_ns", sa.BigInteger(), nullable=False),
        sa.Column("created_ns", sa.BigInteger(), nullable=False),
        sa.Column("delivered_ns", sa.BigInteger(), nullable=True),
    )
    op.create_index("ix_alert_outbox_rule_state", "alert_outbox", ["rule", "state", "id"])
    op.create_table(
        "alert_marks",
        sa.Column("rule", sa.String(64), primary_key=True),
        sa.Column("mark", sa.String(128), primary_key=True),
        sa.Column("value", sa.BigInteger(), nullable=False),
    )


def downgrade() -> None:
    op.drop_table("alert_marks")
    op.drop_index("ix_alert_outbox_rule_state", table_name="alert_outbox")
    op.drop_table("alert_outbox")
    op.drop_table("alert_cursors")
