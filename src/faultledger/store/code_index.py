"""The log's index by fault code (``events_by_code``), kept with the projections.

Rows (fault_code, seq) for every record with a fault code up to the projections' checkpoint,
added in the transaction that moves the checkpoint, with one INSERT … SELECT over the
records since the last one. Records after the checkpoint are found by their seq, which the
log's primary key orders: at most the records of one save interval (``SAVE_EVERY_RECORDS``)
on a running ledger. Why not an index on the log itself: schema.events_by_code.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy import ColumnElement, Connection, and_, delete, func, select, union_all
from sqlalchemy.dialects import postgresql, sqlite

from faultledger.store.schema import PROJECTION_CHECKPOINT, checkpoints, events, events_by_code


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


def add(conn: Connection, after: int, upto: int) -> None:
    """Index the records ``after`` < seq <= ``upto`` (in the caller's transaction). A row
    already there (a checkpoint that once moved back) is kept."""
    if upto <= after:
        return
    rows = (select(events.c.fault_code, events.c.seq)
            .where(events.c.seq > after, events.c.seq <= upto, events.c.fault_code.is_not(None))
            .order_by(events.c.fault_code, events.c.seq))  # appended in key order
    module: Any = postgresql if conn.dialect.name == "postgresql" else sqlite
    conn.execute(module.insert(events_by_code).from_select(["fault_code", "seq"], rows)
                 .on_conflict_do_nothing())


def ensure_complete(conn: Connection, upto: int) -> None:
    """``rebuild``: the index is two columns of the log, not a replay's result, so it is
    kept, unless it does not hold as many rows up to ``upto`` (the checkpoint) as the log
    holds records with a code: then it is made again from the log. (A refill of a million
    rows took a second, a tenth of a rebuild; counting them, a tenth of that. ``verify``
    compares them row by row.)"""
    logged = conn.execute(select(func.count()).select_from(events).where(
        events.c.seq <= upto, events.c.fault_code.is_not(None))).scalar()
    held = conn.execute(select(func.count()).select_from(events_by_code).where(
        events_by_code.c.seq <= upto)).scalar()
    if logged != held:
        conn.execute(delete(events_by_code))
        add(conn, 0, upto)


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


def differences(conn: Connection, upto: int) -> list[str]:
    """Where the index up to ``upto`` (the checkpoint) differs from the log: records with a
    code it lacks, and rows that name no record of that code (``verify``)."""
    indexed = events_by_code.c
    missing = conn.execute(
        select(func.count()).select_from(events)
        .where(events.c.seq <= upto, events.c.fault_code.is_not(None),
               ~select(indexed.seq).where(indexed.fault_code == events.c.fault_code,
                                          indexed.seq == events.c.seq).exists())).scalar()
    stray = conn.execute(
        select(func.count()).select_from(events_by_code)
        .where(indexed.seq <= upto,
               ~select(events.c.seq).where(events.c.seq == indexed.seq,
                                           events.c.fault_code == indexed.fault_code).exists())
    ).scalar()
    problems = []
    if missing:
        problems.append(f"the index by code lacks {missing} record(s) up to the checkpoint")
    if stray:
        problems.append(f"the index by code names {stray} record(s) the log does not hold "
                        "under that code")
    return problems
