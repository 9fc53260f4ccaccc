"""The log's indexes, kept with the projections: by fault code, by time and by event_id.

``events`` has one B-tree, its primary key (seq); every other way into the log is a table of
(key, seq) rows up to the projections' checkpoint (``events_by_code``, ``events_by_time``,
``events_by_id``), added in the transaction that moves the checkpoint, with one INSERT …
SELECT per table over the records since the last save. Records after the checkpoint are
found by their seq, which the primary key orders: at most the records of one save interval
(``SAVE_EVERY_RECORDS``) on a running ledger. Why not indexes on the log itself: a report's
commit writes one page per B-tree it touches (schema.events_by_code, docs/architecture.md
"The log's indexes").
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import Any

from sqlalchemy import (
    ColumnElement,
    CompoundSelect,
    Connection,
    Insert,
    Table,
    and_,
    bindparam,
    delete,
    func,
    literal_column,
    select,
    union_all,
)
from sqlalchemy.dialects import postgresql, sqlite

from faultledger.store import fastpath
from faultledger.store.schema import (
    PROJECTION_CHECKPOINT,
    checkpoints,
    events,
    events_by_code,
    events_by_id,
    events_by_time,
)


def saved_seq() -> ColumnElement[int]:
    """The projections' checkpoint (0 before the first save), read in the statement's own
    snapshot: the rows indexed and the records after them never overlap nor leave a gap."""
    saved = (select(checkpoints.c.seq).where(checkpoints.c.name == PROJECTION_CHECKPOINT)
             .scalar_subquery())
    return func.coalesce(saved, 0)


def of_codes(codes: Sequence[str]) -> ColumnElement[bool]:
    """``events`` rows of these codes: the indexed seqs up to the checkpoint, and the
    records after it, as one list of seqs (so the log is read by its primary key)."""
    saved = saved_seq()
    if len(codes) == 1:
        indexed_code = events_by_code.c.fault_code == codes[0]
        recent_code = events.c.fault_code == codes[0]
    else:
        indexed_code = events_by_code.c.fault_code.in_(list(codes))
        recent_code = events.c.fault_code.in_(list(codes))
    indexed = select(events_by_code.c.seq).where(indexed_code, events_by_code.c.seq <= saved)
    recent = select(events.c.seq).where(events.c.seq > saved, recent_code)
    # The code is checked on the record too: a row left past a checkpoint that moved back
    # can then never put a record under a code it does not have.
    return and_(events.c.seq.in_(union_all(indexed, recent)), recent_code)


def of_times(since_ns: int | None, until_ns: int | None) -> ColumnElement[bool]:
    """``events`` rows with ``occurred_at`` in [since, until) (either bound may be open), as
    ``of_codes`` finds a code's: the indexed seqs and the records after the checkpoint."""
    saved = saved_seq()
    indexed_time: list[ColumnElement[bool]] = []
    recent_time: list[ColumnElement[bool]] = []
    if since_ns is not None:
        indexed_time.append(events_by_time.c.occurred_at_ns >= since_ns)
        recent_time.append(events.c.occurred_at_ns >= since_ns)
    if until_ns is not None:
        indexed_time.append(events_by_time.c.occurred_at_ns < until_ns)
        recent_time.append(events.c.occurred_at_ns < until_ns)
    indexed = select(events_by_time.c.seq).where(*indexed_time, events_by_time.c.seq <= saved)
    recent = select(events.c.seq).where(events.c.seq > saved, *recent_time)
    return and_(events.c.seq.in_(union_all(indexed, recent)), *recent_time)


def existing_ids(conn: Connection, event_ids: Sequence[str]) -> set[str]:
    """Which of these event_ids the log holds: the indexed ones up to the checkpoint and the
    records after it (the writer asks under the write lock, so none can appear meanwhile)."""
    if not event_ids:
        return set()
    wanted = list(event_ids)
    saved = saved_seq()
    indexed = select(events_by_id.c.event_id).where(events_by_id.c.event_id.in_(wanted),
                                                    events_by_id.c.seq <= saved)
    recent = select(events.c.event_id).where(events.c.seq > saved,
                                             events.c.event_id.in_(wanted))
    return {str(event_id) for (event_id,) in conn.execute(union_all(indexed, recent))}


def indexed_ids(conn: Connection, event_ids: Sequence[str]) -> tuple[set[str], int]:
    """Which of these event_ids ``events_by_id`` holds, and the projections' checkpoint, in
    one statement on the driver's cursor (the writer asks it for every group with explicit
    event_ids): a writer that knows every record after the checkpoint (its own and those
    it caught up with, ``service.writer``) need not read them. Any row counts, also one
    past the checkpoint: rows are only ever added from records of the log."""
    wanted = list(event_ids)
    rows = fastpath.fetch_all(conn, _indexed_ids_statement(len(wanted)),
                              {f"id{n}": event_id for n, event_id in enumerate(wanted)})
    ids: set[str] = set()
    saved = 0
    for event_id, seq in rows:
        if event_id is None:
            saved = int(seq)
        else:
            ids.add(str(event_id))
    return ids, saved


@lru_cache(maxsize=64)
def _indexed_ids_statement(count: int) -> CompoundSelect[Any]:
    found = select(events_by_id.c.event_id, literal_column("-1")).where(
        events_by_id.c.event_id.in_([bindparam(f"id{n}") for n in range(count)]))
    return union_all(found, select(literal_column("NULL"), saved_seq()))


_KEYS: tuple[tuple[Table, str], ...] = (
    (events_by_code, "fault_code"),
    (events_by_time, "occurred_at_ns"),
    (events_by_id, "event_id"),
)
"""Each index and the column of ``events`` it is keyed by (with seq)."""


def add(conn: Connection, after: int, upto: int) -> None:
    """Index the records ``after`` < seq <= ``upto`` (in the caller's transaction). A row
    already there (a checkpoint that once moved back) is kept."""
    if upto <= after:
        return
    for index, key in _KEYS:
        _fill(conn, index, key, after, upto)


def _fill(conn: Connection, index: Table, key: str, after: int, upto: int) -> None:
    fastpath.execute(conn, _fill_statement(index, key, conn.dialect.name),
                     {"after": after, "upto": upto})


@lru_cache(maxsize=8)
def _fill_statement(index: Table, key: str, dialect: str) -> Insert:
    """Built and compiled once: every save runs these three (SQLAlchemy's building and
    executing them cost more than SQLite's work on a save's thousand records)."""
    column = events.c[key]
    rows = (select(column, events.c.seq)
            .where(events.c.seq > bindparam("after"), events.c.seq <= bindparam("upto"),
                   column.is_not(None))
            .order_by(column, events.c.seq))  # appended in key order
    module: Any = postgresql if dialect == "postgresql" else sqlite
    statement: Insert = (module.insert(index).from_select([key, "seq"], rows)
                         .on_conflict_do_nothing())
    return statement


def ensure_complete(conn: Connection, upto: int) -> None:
    """``rebuild``: the indexes are columns of the log, not a replay's result, so they are
    kept, unless one does not hold as many rows up to ``upto`` (the checkpoint) as the log
    holds records with its key: then that one is made again from the log. (A refill of a
    million rows took a second, a tenth of a rebuild; counting them, a tenth of that.
    ``verify`` compares them row by row.)"""
    counted = conn.execute(select(*(func.count(events.c[key]) for _, key in _KEYS))
                           .where(events.c.seq <= upto)).one()  # one pass over the log
    for (index, key), logged in zip(_KEYS, counted, strict=True):
        held = conn.execute(select(func.count()).select_from(index).where(
            index.c.seq <= upto)).scalar()
        if logged != held:
            conn.execute(delete(index))
            _fill(conn, index, key, 0, upto)


def distinct_codes(conn: Connection, prefix: str = "") -> list[str]:
    """The stored fault codes in order (those starting with ``prefix`` on SQLite): one index
    seek per indexed code (a loose scan), and the codes of the records after the checkpoint.

    On SQLite (binary collation) the scan starts at ``prefix`` and stops after the codes that
    start with it; elsewhere a collation may order codes differently, so every code is
    visited (the caller matches them)."""
    bounded = bool(prefix) and conn.dialect.name == "sqlite"
    column = events_by_code.c.fault_code
    found: set[str] = set()
    last: str | None = None
    while True:
        if last is not None:
            condition = column > last
        elif bounded:
            condition = column >= prefix
        else:
            condition = column.is_not(None)
        code = conn.execute(select(func.min(column)).where(condition)).scalar()
        if code is None or (bounded and not str(code).startswith(prefix)):
            break
        last = str(code)
        found.add(last)
    recent = select(events.c.fault_code).where(events.c.seq > saved_seq(),
                                               events.c.fault_code.is_not(None)).distinct()
    found.update(str(code) for (code,) in conn.execute(recent))
    if bounded:
        return sorted(code for code in found if code.startswith(prefix))
    return sorted(found)


_NAMES = {"events_by_code": "the index by code", "events_by_time": "the index by time",
          "events_by_id": "the index by event_id"}


def differences(conn: Connection, upto: int) -> list[str]:
    """Where an index up to ``upto`` (the checkpoint) differs from the log (records with a
    key it lacks, rows that name no record with that key), and how many records repeat an
    earlier one's event_id (``verify``): the log has no UNIQUE constraint, the writer checks."""
    problems = []
    for index, key in _KEYS:
        column, indexed = events.c[key], index.c
        missing = conn.execute(
            select(func.count()).select_from(events)
            .where(events.c.seq <= upto, column.is_not(None),
                   ~select(indexed.seq).where(indexed[key] == column,
                                              indexed.seq == events.c.seq).exists())).scalar()
        stray = conn.execute(
            select(func.count()).select_from(index)
            .where(indexed.seq <= upto,
                   ~select(events.c.seq).where(events.c.seq == indexed.seq,
                                               column == indexed[key]).exists())).scalar()
        name = _NAMES[index.name]
        if missing:
            problems.append(f"{name} lacks {missing} record(s) up to the checkpoint")
        if stray:
            problems.append(f"{name} names {stray} record(s) the log does not hold with "
                            f"that {key}")
    repeats = _repeated_ids(conn, upto, trust_index=not any(
        problem.startswith(_NAMES["events_by_id"]) for problem in problems))
    if repeats:
        problems.append(f"{repeats} record(s) repeat the event_id of an earlier one")
    return problems


def _repeated_ids(conn: Connection, upto: int, trust_index: bool) -> int:
    """How many records repeat an earlier record's event_id. With ``events_by_id`` found
    equal to the log up to ``upto``, those records' ids are distinct (one row per id), so only
    the records after it are counted: each one unless it is the first of an id the index does
    not hold. Otherwise the whole log is counted (a sort of every event_id)."""
    if not trust_index:
        total, distinct = conn.execute(
            select(func.count(), func.count(events.c.event_id.distinct()))
            .select_from(events)).one()
        return int(total) - int(distinct)
    indexed = select(events_by_id.c.seq).where(events_by_id.c.event_id == events.c.event_id,
                                               events_by_id.c.seq <= upto).exists()
    recent = conn.execute(select(func.count()).select_from(events)
                          .where(events.c.seq > upto)).scalar_one()
    first = conn.execute(select(func.count(events.c.event_id.distinct()))
                         .where(events.c.seq > upto, ~indexed)).scalar_one()
    return int(recent) - int(first)
