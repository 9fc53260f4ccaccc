"""The log's identity as a projection: robot_id and ledger_id of its ``ledger_identified`` record.

Identity records (kind ``ledger_identified``) need no change of the event log: they are
ordinary records with a NULL fault code. This revision adds the one-row table that lets an
open know the identity without scanning the log. A log written before it has no identity
record (its next writer appends one); a log that has one (downgraded and upgraded again)
gets the row from its first such record up to the projections' checkpoint, as a replay
would. No record is touched.

Revision ID: 0004_ledger_identity
Revises: 0003_goal_outcomes
Create Date: 2026-12-01
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import context, op

revision: str = "0004_ledger_identity"
down_revision: str | None = "0003_goal_outcomes"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

_SEQ = sa.BigInteger().with_variant(sa.Integer(), "sqlite")
_EVENTS = sa.table("events", sa.column("seq", sa.BigInteger()), sa.column("kind", sa.String()),
                   sa.column("payload", sa.Text()))
_CHECKPOINTS = sa.table("checkpoints", sa.column("name", sa.String()),
                        sa.column("seq", sa.BigInteger()))


def upgrade() -> None:
    identity = op.create_table(
        "ledger_identity",
        sa.Column("seq", _SEQ, primary_key=True, autoincrement=False),
        sa.Column("robot_id", sa.String(128), nullable=False),
        sa.Column("ledger_id", sa.String(36), nullable=False),
    )
    if context.is_offline_mode():
        return
    projected = (sa.select(_CHECKPOINTS.c.seq).where(_CHECKPOINTS.c.name == "projection")
                 .scalar_subquery())
    first = op.get_bind().execute(
        sa.select(_EVENTS.c.seq, _EVENTS.c.payload)
        .where(_EVENTS.c.kind == "ledger_identified", _EVENTS.c.seq <= projected)
        .order_by(_EVENTS.c.seq).limit(1)).first()
    if first is not None:
        payload = json.loads(first.payload)
        op.bulk_insert(identity, [{"seq": first.seq, "robot_id": payload["robot_id"],
                                   "ledger_id": payload["ledger_id"]}])


def downgrade() -> None:
    op.drop_table("ledger_identity")
