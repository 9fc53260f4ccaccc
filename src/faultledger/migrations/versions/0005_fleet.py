"""The fleet central's directory of robot logs.

A central (docs/fleet.md) keeps each robot log it receives as a log of its own (a PostgreSQL
schema, or a SQLite file beside the central's); ``fleet_chains`` lists them: which robot,
which log, how far it is held and when the robot last made contact. A robot's own database
has the table too, empty. No record is touched.

Revision ID: 0005_fleet
Revises: 0004_ledger_identity
Create Date: 2026-11-26
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005_fleet"
down_revision: str | None = "0004_ledger_identity"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "fleet_chains",
        sa.Column("chain_id", sa.Integer(), primary_key=True, autoincrement=True),
        sa.Column("ledger_id", sa.String(36), nullable=False, unique=True),
        sa.Column("robot_id", sa.String(128), nullable=False),
        sa.Column("last_seq", sa.BigInteger(), nullable=False),
        sa.Column("last_hash", sa.String(64), nullable=False),
        sa.Column("head_seq", sa.BigInteger(), nullable=False),
        sa.Column("first_contact_ns", sa.BigInteger(), nullable=False),
        sa.Column("last_contact_ns", sa.BigInteger(), nullable=False),
        sa.Column("last_recorded_ns", sa.BigInteger(), nullable=False),
        sa.Column("complete_until_ns", sa.BigInteger(), nullable=False),
    )
    op.create_index("ix_fleet_chains_robot", "fleet_chains", ["robot_id", "first_contact_ns"])


def downgrade() -> None:
    op.drop_index("ix_fleet_chains_robot", "fleet_chains")
    op.drop_table("fleet_chains")
