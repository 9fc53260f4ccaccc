"""SQLAlchemy tables; Alembic migrations in ``faultledger/migrations/`` create and change them."""

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
    Column("event_id", String(36), nullable=False),
    Column("kind", String(40), nullable=False),
    Column("fault_code", String(128), nullable=True),
    Column("source_id", Text, nullable=True),
    Column("payload", Text, nullable=False),
    Column("occurred_at_ns", BigInteger, nullable=False),
    Column("recorded_at_ns", BigInteger, nullable=False),
    Column("schema_version", Integer, nullable=False),
    Column("hash", String(64), nullable=False),
)
"""The log: its one B-tree is the primary key, seq. Its indexes by code, time and event_id
are tables of their own, kept with the projections (``events_by_*``, store/log_index.py);
event_ids are unique because the writer checks them under the write lock (Alembic 0010
dropped the UNIQUE constraint; ``verify`` checks)."""

events_by_code = Table(
    "events_by_code",
    metadata,
    Column("fault_code", String(128), primary_key=True),
    Column("seq", BigInteger, primary_key=True, autoincrement=False),
    sqlite_with_rowid=False,
)
"""The seqs of each fault code's records, up to the projections' checkpoint (Alembic 0009):
the log's index by code, written with the projections instead of with every record.

An index on ``events (fault_code, seq)`` put each report into the leaf page of its code, so
a group commit of eight reports over eight codes wrote eight more pages into the WAL, and as
the log grew past the page cache each of them was read back too: on a log of a million
records eight reporters ran at 9,150 reports/s instead of 12,600 without it
(docs/performance.md, "Eleventh round"). Written once per save (every 1,000 records at
most), a code's leaf page takes all of its records since the last save at once. Reads by
code take these seqs and the records after the checkpoint (``log_index.of_codes``); rows
past the checkpoint (left by a checkpoint that moved back) are never read."""

events_by_time = Table(
    "events_by_time",
    metadata,
    Column("occurred_at_ns", BigInteger, primary_key=True, autoincrement=False),
    Column("seq", BigInteger, primary_key=True, autoincrement=False),
    sqlite_with_rowid=False,
)
"""The seqs of the records by ``occurred_at`` up to the checkpoint (Alembic 0010), for reads
bounded by time: ``ix_events_occurred_at`` was one more page in every report's commit (one
reporter: 5,306–5,529 against 5,603–5,792 reports/s without it, docs/performance.md,
"Twelfth round")."""

events_by_id = Table(
    "events_by_id",
    metadata,
    Column("event_id", String(36), primary_key=True),
    Column("seq", BigInteger, nullable=False),
    sqlite_with_rowid=False,
)
"""The seq of each event_id up to the checkpoint (Alembic 0010): what the writer checks a
repeated event_id against (``log_index.indexed_ids``), instead of a UNIQUE index on
``events`` written with every record."""

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
    # Alembic 0007: the operator's day and the episodes (docs/semantics.md).
    Column("first_ever_ns", BigInteger, nullable=False, server_default="0"),
    Column("episode_failures", Integer, nullable=False, server_default="0"),
    Column("total_failures", Integer, nullable=False, server_default="0"),
    Column("confirmed_ns", BigInteger, nullable=False, server_default="0"),
    Column("acknowledged", Text, nullable=True),  # JSON [actor, note, at_ns, seq]
    Column("shelved", Text, nullable=True),  # JSON [actor, reason, at_ns, until_ns, seq]
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
PROJECTION_CHECKPOINT = "projection"
"""``projection`` row: the seq the projections include, the hash of that record, and the seq
of the policy_changed record in force (so startup finds the policy without a log scan).

The hash anchors the head of the chain, so deleting the newest records is detected too.
Every index on ``events`` costs each append; only the ones queries need exist.
"""

ledger_identity = Table(
    "ledger_identity",
    metadata,
    Column("seq", SeqType, primary_key=True, autoincrement=False),
    Column("robot_id", String(128), nullable=False),
    Column("ledger_id", String(36), nullable=False),
)
"""At most one row (Alembic 0004): the log's first ``ledger_identified`` record and its seq,
so an open knows the identity without scanning the log."""

# -- statistics projections (docs/statistics.md, "How they are served") ------------------------
STAT_FLAGS = ("failed", "passed", "activation", "occurrence", "confirmation", "heal", "clear")
"""What a statistics fact counts, and what the sums tables add up (docs/statistics.md)."""


def _flag_columns() -> list[Column[int]]:
    return [Column(name, Integer, nullable=False) for name in STAT_FLAGS]


stat_facts = Table(
    "stat_facts",
    metadata,
    Column("seq", SeqType, primary_key=True, autoincrement=False),
    Column("at_ns", BigInteger, nullable=False),
    Column("fault_code", String(128), nullable=False),
    Column("source_id", Text, nullable=False),
    Column("severity", Integer, nullable=False),
    *_flag_columns(),
    Column("chatter", Integer, nullable=False),
)
Index("ix_stat_facts_at", stat_facts.c.at_ns)
Index("ix_stat_facts_code_at", stat_facts.c.fault_code, stat_facts.c.at_ns)
# Covering (time, code) for the per-period top-10 and chattering counts.
Index("ix_stat_facts_confirmation_at", stat_facts.c.at_ns, stat_facts.c.fault_code,
      sqlite_where=stat_facts.c.confirmation == 1,
      postgresql_where=stat_facts.c.confirmation == 1)
# The activations, for the e-stops (Alembic 0006).
Index("ix_stat_facts_activation", stat_facts.c.fault_code, stat_facts.c.at_ns,
      sqlite_where=stat_facts.c.activation == 1, postgresql_where=stat_facts.c.activation == 1)
Index("ix_stat_facts_chatter_at", stat_facts.c.at_ns, stat_facts.c.fault_code,
      sqlite_where=stat_facts.c.chatter == 1, postgresql_where=stat_facts.c.chatter == 1)

stat_episodes = Table(
    "stat_episodes",
    metadata,
    Column("start_seq", SeqType, primary_key=True, autoincrement=False),
    Column("fault_code", String(128), nullable=False),
    Column("source_id", Text, nullable=False),
    Column("severity", Integer, nullable=False),
    Column("start_ns", BigInteger, nullable=False),
    Column("end_seq", BigInteger, nullable=True),
    Column("end_ns", BigInteger, nullable=True),
)
Index("ix_stat_episodes_code_start", stat_episodes.c.fault_code, stat_episodes.c.start_ns)
Index("ix_stat_episodes_start", stat_episodes.c.start_ns)
Index("ix_stat_episodes_end", stat_episodes.c.end_ns)
STALE_AFTER_NS = 24 * 3600 * 1_000_000_000
_LONG = stat_episodes.c.end_ns - stat_episodes.c.start_ns >= STALE_AFTER_NS
Index("ix_stat_episodes_long_end", stat_episodes.c.end_ns, sqlite_where=_LONG,
      postgresql_where=_LONG)

def _sums_table(name: str, key: str) -> Table:
    """Sums of the statistics facts per ``key`` (a minute or an hour of ``at_ns``)."""
    return Table(
        name,
        metadata,
        Column(key, BigInteger, primary_key=True, autoincrement=False),
        *_flag_columns(),
        Column("starts", Integer, nullable=False),
        Column("start_offset_ns", BigInteger, nullable=False),
        Column("ends", Integer, nullable=False),
        Column("end_offset_ns", BigInteger, nullable=False),
        Column("repairs", Integer, nullable=False),
        Column("repair_ns", BigInteger, nullable=False),
        Column("aborted_goals", Integer, nullable=False, server_default="0"),
        Column("canceled_goals", Integer, nullable=False, server_default="0"),
        Column("succeeded_goals", Integer, nullable=False, server_default="0"),
    )


stat_minutes = _sums_table("stat_minutes", "minute")
"""Sums per minute of ``at_ns`` (minute = at_ns // 60e9). Episode starts and ends keep their
offsets within the minute, so active time over whole minutes is exact. Repairs count in
the minute of the record that ended the episode; ``ends`` in the minute where its time in
CONFIRMED stops (later, when the reporter's clock ran backwards). The goal columns (Alembic
0003) count goal outcome records by status."""
# The minutes with confirmations, for the flood windows (Alembic 0006).
Index("ix_stat_minutes_confirmation", stat_minutes.c.minute, stat_minutes.c.confirmation,
      sqlite_where=stat_minutes.c.confirmation > 0,
      postgresql_where=stat_minutes.c.confirmation > 0)

stat_hours = _sums_table("stat_hours", "hour")
"""The same sums per hour (hour = at_ns // 3600e9, offsets within the hour; Alembic 0006): a
period of whole hours (a shift, a day) is read from 60 times fewer rows."""

stat_operator = Table(
    "stat_operator",
    metadata,
    Column("seq", SeqType, primary_key=True, autoincrement=False),
    Column("kind", String(8), nullable=False),
    Column("fault_code", String(128), nullable=False),
    Column("source_id", Text, nullable=False),
    Column("severity", Integer, nullable=False),
    Column("at_ns", BigInteger, nullable=False),
    Column("delay_ns", BigInteger, nullable=True),
    Column("until_ns", BigInteger, nullable=True),
    Column("end_seq", BigInteger, nullable=True),
    Column("end_ns", BigInteger, nullable=True),
)
"""Acknowledgements and shelvings (Alembic 0007; docs/statistics.md, "The operator's day"):
few rows, read whole for a range (acknowledgements in it, shelvings overlapping it)."""
Index("ix_stat_operator_at", stat_operator.c.at_ns)

stat_goals = Table(
    "stat_goals",
    metadata,
    Column("seq", SeqType, primary_key=True, autoincrement=False),
    Column("at_ns", BigInteger, nullable=False),
    Column("action", String(256), nullable=False),
    Column("status", String(16), nullable=False),
    Column("server_node", Text, nullable=False),
)
"""One row per goal outcome record (Alembic 0003): what the goal figures are counted from
when a query groups by action or its range does not end on a whole minute."""
Index("ix_stat_goals_at", stat_goals.c.at_ns)
Index("ix_stat_goals_action_at", stat_goals.c.action, stat_goals.c.at_ns)

stat_codes = Table(
    "stat_codes",
    metadata,
    Column("fault_code", String(128), primary_key=True),
    Column("last_failed", Boolean, nullable=False),
    Column("activations", Text, nullable=False),
    Column("episode_start_seq", BigInteger, nullable=True),
)
"""The statistics fold's per-code state (domain.statistics.CodeTrack)."""

# -- a fleet central's directory of robot logs (store/fleet_log.py, docs/fleet.md) ------------
fleet_chains = Table(
    "fleet_chains",
    metadata,
    Column("chain_id", Integer, primary_key=True, autoincrement=True),
    Column("ledger_id", String(36), nullable=False, unique=True),
    Column("robot_id", String(128), nullable=False),
    Column("last_seq", BigInteger, nullable=False),
    Column("last_hash", String(64), nullable=False),
    Column("head_seq", BigInteger, nullable=False),
    Column("first_contact_ns", BigInteger, nullable=False),
    Column("last_contact_ns", BigInteger, nullable=False),
    Column("last_recorded_ns", BigInteger, nullable=False),
    Column("complete_until_ns", BigInteger, nullable=False),
)
"""``last_seq``/``last_hash``: how far the central holds the log (its own log's head is the
truth; this row follows it after each push). ``head_seq``: the robot's newest seq at its last
contact. ``complete_until_ns``: the time up to which the central holds the robot's whole log."""
Index("ix_fleet_chains_robot", fleet_chains.c.robot_id, fleet_chains.c.first_contact_ns)

# -- alert delivery (store/alert_outbox.py, docs/alerts.md; Alembic 0008) ----------------------
alert_cursors = Table(
    "alert_cursors",
    metadata,
    Column("rule", String(64), primary_key=True),
    Column("seq", BigInteger, nullable=False),
    Column("holder", String(160), nullable=True),
    Column("lease_until_ns", BigInteger, nullable=False),
)
"""Per rule: the last seq its scan has turned into outbox rows, and the lease: which process
delivers the rule (``holder``) until when; taken over once expired."""

alert_outbox = Table(
    "alert_outbox",
    metadata,
    Column("id", SeqType, primary_key=True, autoincrement=True),
    Column("rule", String(64), nullable=False),
    Column("key", String(255), nullable=False, unique=True),
    Column("seq", BigInteger, nullable=False),
    Column("event", String(32), nullable=False),
    Column("fault_code", String(128), nullable=True),
    Column("record_ns", BigInteger, nullable=False),
    Column("payload", Text, nullable=False),
    Column("state", String(16), nullable=False),
    Column("attempts", Integer, nullable=False),
    Column("last_error", Text, nullable=True),
    Column("next_attempt_ns", BigInteger, nullable=False),
    Column("created_ns", BigInteger, nullable=False),
    Column("delivered_ns", BigInteger, nullable=True),
)
"""One row per delivery (idempotency ``key``), in the order the scan decided them (``id``);
``payload`` is the alert (domain.alerts.Alert) as JSON, ``record_ns`` the recording time of
the record it anchors on (the lag)."""
Index("ix_alert_outbox_rule_state", alert_outbox.c.rule, alert_outbox.c.state,
      alert_outbox.c.id)

alert_marks = Table(
    "alert_marks",
    metadata,
    Column("rule", String(64), primary_key=True),
    Column("mark", String(128), primary_key=True),
    Column("value", BigInteger, nullable=False),
)
"""What a rule's scan remembers between scans, moved in the transaction that moves its
cursor: confirmations per 10-minute window (``flood:<window_ns>``) and the robot logs it
has alerted as lagging (``lag:<ledger_id>``)."""
