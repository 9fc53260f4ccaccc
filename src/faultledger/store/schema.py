"""SQLAlchemy tables; Alembic migrations in ``migrations/`` create and change them."""

from __future__ import annotations

from sqlalchemy import (
    BigInteger,
    Boolean,
    Column,
    Index,
    Integer,
    MetaData,
    String,
    Table,
    Text,
)

metadata = MetaData()

# SQLite only makes "INTEGER PRIMARY KEY" the rowid; BIGINT elsewhere (PostgreSQL).
SeqType = BigInteger().with_variant(Integer(), "sqlite")

events = Table(
    "events",
    metadata,
    Column("seq", SeqType, primary_key=True, autoincrement=False),
    Column("event_id", String(36), nullable=False, unique=True),
    Column("kind", String(40), nullable=False),
    Column("fault_code", String(128), nullable=True),
    Column("source_id", Text, nullable=True),
    Column("payload", Text, nullable=False),
    Column("occurred_at_ns", BigInteger, nullable=False),
    Column("recorded_at_ns", BigInteger, nullable=False),
    Column("schema_version", Integer, nullable=False),
    Column("hash", String(64), nullable=False),
)
Index("ix_events_fault_code_seq", events.c.fault_code, events.c.seq)
Index("ix_events_occurred_at", events.c.occurred_at_ns)

faults = Table(
    "faults",
    metadata,
    Column("fault_code", String(128), primary_key=True),
    Column("severity", Integer, nullable=False),
    Column("description", Text, nullable=False),
    Column("first_occurred_ns", BigInteger, nullable=False),
    Column("last_occurred_ns", BigInteger, nullable=False),
    Column("last_passed_ns", BigInteger, nullable=False),
    Column("occurrence_count", Integer, nullable=False),
    Column("status", String(16), nullable=False),
    Column("reporting_sources", Text, nullable=False),
    Column("debounce_counter", Integer, nullable=False),
    Column("last_report_failed", Boolean, nullable=False),
)

transitions = Table(
    "transitions",
    metadata,
    Column("seq", SeqType, primary_key=True, autoincrement=False),
    Column("fault_code", String(128), nullable=False),
    Column("from_status", String(16), nullable=True),
    Column("to_status", String(16), nullable=False),
    Column("at_ns", BigInteger, nullable=False),
    Column("cause", String(16), nullable=False),
    Column("source_id", Text, nullable=False),
)
Index("ix_transitions_fault_code_seq", transitions.c.fault_code, transitions.c.seq)
Index("ix_transitions_at", transitions.c.at_ns)

checkpoints = Table(
    "checkpoints",
    metadata,
    Column("name", String(40), primary_key=True),
    Column("seq", BigInteger, nullable=False),
    Column("hash", String(64), nullable=False),
    Column("policy_seq", BigInteger, nullable=False),
)
"""``projection`` row: the seq the projections include, the hash of that record, and the seq
of the policy_changed record in force (so startup finds the policy without a log scan).

The hash anchors the head of the chain, so deleting the newest records is detected too.
Every index on ``events`` costs each append; only the ones queries need exist.
"""
