"""The append-only event log: append, read in seq order, query, and check the hash chain."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from fnmatch import fnmatchcase
from typing import Any, NamedTuple

from sqlalchemy import Connection, Integer, Select, bindparam, func, select

from faultledger.domain.events import (
    POLICY_CHANGED,
    LogRecord,
    PolicyChanged,
    UnknownRecordError,
    decode,
    fault_code_of,
    source_of,
)
from faultledger.domain.fleet import PushedRecord
from faultledger.domain.integrity import (
    GENESIS_HASH,
    parse_json,
    payload_json,
    record_hash,
    walk_chain,
)
from faultledger.domain.types import tuple_new
from faultledger.store import fastpath, log_index
from faultledger.store.schema import events

READ_CHUNK = 5_000


_HEAD = select(events.c.seq, events.c.hash).order_by(events.c.seq.desc()).limit(1)


def head(conn: Connection) -> tuple[int, str]:
    """Seq and hash of the newest record, (0, GENESIS_HASH) for an empty log."""
    row = fastpath.fetch_one(conn, _HEAD)
    return (0, GENESIS_HASH) if row is None else (int(row[0]), str(row[1]))


def append(conn: Connection, records: Sequence[LogRecord], prev_hash: str) -> str:
    """Insert records (seq already assigned, gap-free) chaining their hashes; returns the last."""
    rows: list[tuple[Any, ...]] = []
    for seq, event_id, event, occurred, recorded, version, _ in records:
        payload = payload_json(event)
        code = fault_code_of(event)
        source = source_of(event)
        prev_hash = record_hash(prev_hash, seq, event_id, event.kind, code, source, payload,
                                occurred, recorded, version)
        rows.append((seq, event_id, event.kind, code, source, payload, occurred, recorded,
                     version, prev_hash))
    fastpath.insert_tuples(conn, events, _COLUMNS, rows)
    return prev_hash


_COLUMNS = ("seq", "event_id", "kind", "fault_code", "source_id", "payload",
            "occurred_at_ns", "recorded_at_ns", "schema_version", "hash")


def append_verbatim(conn: Connection, records: Sequence[PushedRecord]) -> None:
    """Insert records exactly as another log stored them (a fleet central's copy of a robot
    log; the caller checked their hashes and that they continue this log)."""
    fastpath.insert_tuples(conn, events, _COLUMNS, [
        (r.seq, r.event_id, r.kind, r.fault_code, r.source_id, r.payload, r.occurred_at_ns,
         r.recorded_at_ns, r.schema_version, r.hash) for r in records])


def hashes_between(conn: Connection, first_seq: int, last_seq: int) -> dict[int, str]:
    """Stored hashes of records first_seq..last_seq."""
    rows: Any = conn.execute(select(events.c.seq, events.c.hash).where(  # Rows, not tuples
        events.c.seq >= first_seq, events.c.seq <= last_seq))  # (compiled code checks)
    return {int(seq): str(digest) for seq, digest in rows}


def _to_record(row: Sequence[Any]) -> LogRecord:
    """A stored row (columns in table order) as a LogRecord; positional for replay speed."""
    seq, event_id, kind, _code, _source, payload, occurred, recorded, version, digest = row
    record: LogRecord = tuple_new(LogRecord, (  # see tuple_new
        seq, event_id, decode(kind, version, parse_json(payload)), occurred, recorded, version,
        digest))
    return record


_AFTER = bindparam("after", type_=Integer)
_UPTO = bindparam("upto", type_=Integer)
_CHUNK = bindparam("chunk", type_=Integer)
_ALL = select(events).where(events.c.seq > _AFTER).order_by(events.c.seq)
_ALL_UPTO = _ALL.where(events.c.seq <= _UPTO)
_PAGE = _ALL.limit(_CHUNK)
_PAGE_UPTO = _ALL_UPTO.limit(_CHUNK)


def _rows(conn: Connection, after: int = 0, upto: int | None = None) -> Iterator[tuple[Any, ...]]:
    """Stored rows in seq order, fetched in keyset pages so no huge result is held."""
    statement = _PAGE if upto is None else _PAGE_UPTO
    while True:
        rows = fastpath.fetch_all(conn, statement, {"after": after, "upto": upto,
                                                    "chunk": READ_CHUNK})
        yield from rows
        if len(rows) < READ_CHUNK:
            return
        after = rows[-1][0]


def read(conn: Connection, after_seq: int = 0, upto_seq: int | None = None) -> Iterator[LogRecord]:
    for row in _rows(conn, after_seq, upto_seq):
        yield _to_record(row)


def read_to_end(conn: Connection, after_seq: int = 0,
                upto_seq: int | None = None) -> Iterator[LogRecord]:
    """``read`` for a replay that applies every record it is given: one statement whose
    rows come while the replay works (``fastpath.stream``), where ``read`` asks page by page.
    Nothing else may run on ``conn`` until the last record."""
    statement = _ALL if upto_seq is None else _ALL_UPTO
    rows = fastpath.stream(conn, statement, {"after": after_seq, "upto": upto_seq}, READ_CHUNK)
    try:
        for row in rows:
            yield _to_record(row)
    finally:
        rows.close()  # now, also when a record cannot be read: the connection is free again


GLOB_CHARACTERS = "*?["
"""A code pattern holding one of these is an fnmatch glob; any other is an exact code."""


def is_glob(pattern: str) -> bool:
    return any(char in pattern for char in GLOB_CHARACTERS)


@dataclass(frozen=True, slots=True)
class RecordFilter:
    """What ``find`` selects; every given condition must hold.

    ``codes`` are exact codes or case-sensitive fnmatch globs (any of them matches);
    ``from_seq``/``to_seq`` are inclusive, ``since_ns``/``until_ns`` bound ``occurred_at``
    as [since, until). ``descending`` gives the newest first (``limit`` then keeps the
    newest).
    """

    fault_code: str | None = None
    source_id: str | None = None
    since_ns: int | None = None
    until_ns: int | None = None
    kinds: tuple[str, ...] = ()
    limit: int | None = None
    codes: tuple[str, ...] = ()
    from_seq: int | None = None
    to_seq: int | None = None
    descending: bool = False


def find(conn: Connection, where: RecordFilter) -> list[LogRecord]:
    """Records matching every given filter; times compare with ``occurred_at`` in [since, until)."""
    return list(iter_find(conn, where))


def iter_find(conn: Connection, where: RecordFilter) -> Iterator[LogRecord]:
    """``find`` streamed: one statement whose rows are fetched in chunks as they are used."""
    query = filtered(conn, select(events), where)
    if query is not None:
        for row in stream_rows(conn, query):
            yield _to_record(row)


class StoredRecord(NamedTuple):
    """A record exactly as stored, with the hash of the record before it.

    ``payload_json`` is the stored canonical text (not an upcast of it): with ``prev_hash`` it
    is all ``record_hash`` needs, so an export can be checked without the database.
    ``prev_hash`` is None when record ``seq - 1`` is missing.
    """

    seq: int
    event_id: str
    kind: str
    fault_code: str | None
    source_id: str | None
    payload_json: str
    occurred_at_ns: int
    recorded_at_ns: int
    schema_version: int
    hash: str
    prev_hash: str | None


_PREVIOUS = events.alias("previous")


def iter_stored(conn: Connection, where: RecordFilter) -> Iterator[StoredRecord]:
    """Rows matching ``where`` as stored (no decoding), each joined with its predecessor's hash."""
    base = (select(*events.c, _PREVIOUS.c.hash)
            .select_from(events.outerjoin(_PREVIOUS, _PREVIOUS.c.seq == events.c.seq - 1)))
    query = filtered(conn, base, where)
    if query is None:
        return
    for row in stream_rows(conn, query):
        seq, event_id, kind, code, source, payload, occurred, recorded, version, digest, prev = row
        if prev is None and seq == 1:
            prev = GENESIS_HASH
        yield StoredRecord(int(seq), event_id, kind, code, source, payload, int(occurred),
                           int(recorded), int(version), digest, prev)


def stream_rows(conn: Connection, query: Select[Any]) -> Iterator[Sequence[Any]]:
    """Rows of one statement in chunks: SQLite steps lazily, PostgreSQL uses a server cursor."""
    result = conn.execute(query.execution_options(yield_per=READ_CHUNK))
    for chunk in result.partitions():
        yield from chunk


def count_matching(conn: Connection, where: RecordFilter) -> int:
    """How many records match ``where`` (its ``limit`` aside): an index count when a code,
    seq range or time bounds it, a pass over the log otherwise."""
    query = filtered(conn, select(func.count()).select_from(events),
                      replace(where, limit=None), ordered=False)
    return 0 if query is None else int(conn.execute(query).scalar() or 0)


def filtered(conn: Connection, query: Select[Any], where: RecordFilter, *,
              ordered: bool = True) -> Select[Any] | None:
    """``query`` restricted by ``where`` in seq order (newest first when ``descending``);
    None when no stored code can match."""
    c = events.c
    if ordered:
        query = query.order_by(c.seq.desc() if where.descending else c.seq)
    codes = [] if where.fault_code is None else [where.fault_code]
    if where.codes:
        found = matching_codes(conn, where.codes)
        codes = [code for code in codes if code in found] if codes else found
        if not codes:
            return None
    if codes:
        query = query.where(log_index.of_codes(codes))
    timed = where.since_ns is not None or where.until_ns is not None
    if timed and not codes and where.from_seq is None and where.to_seq is None:
        query = query.where(log_index.of_times(where.since_ns, where.until_ns))
    else:  # a code's records or a seq range bound the read already
        if where.since_ns is not None:
            query = query.where(c.occurred_at_ns >= where.since_ns)
        if where.until_ns is not None:
            query = query.where(c.occurred_at_ns < where.until_ns)
    if where.source_id is not None:
        query = query.where(c.source_id == where.source_id)
    if where.from_seq is not None:
        query = query.where(c.seq >= where.from_seq)
    if where.to_seq is not None:
        query = query.where(c.seq <= where.to_seq)
    if where.kinds:
        query = query.where(c.kind.in_(where.kinds))
    if where.limit is not None:
        query = query.limit(where.limit)
    return query


def matching_codes(conn: Connection, patterns: Sequence[str]) -> list[str]:
    """Exact codes as given plus the stored codes a glob matches (fnmatch, case-sensitive).

    Globs are matched in Python against the distinct stored codes (``log_index``), so the
    records themselves are then selected by code through the index with a plain ``IN``.
    """
    found = {pattern for pattern in patterns if not is_glob(pattern)}
    globs = [pattern for pattern in patterns if is_glob(pattern)]
    if globs:
        prefix = _common_prefix([_literal_prefix(g) for g in globs])
        found.update(code for code in log_index.distinct_codes(conn, prefix)
                     if any(fnmatchcase(code, g) for g in globs))
    return sorted(found)


def _literal_prefix(pattern: str) -> str:
    cut = min((i for i, char in enumerate(pattern) if char in GLOB_CHARACTERS),
              default=len(pattern))
    return pattern[:cut]


def _common_prefix(texts: Sequence[str]) -> str:
    """Longest string every text starts with (character by character)."""
    first, last = min(texts), max(texts)
    size = next((i for i, (a, b) in enumerate(zip(first, last, strict=False)) if a != b),
                min(len(first), len(last)))
    return first[:size]


def hash_at(conn: Connection, seq: int) -> str | None:
    """The stored hash of record ``seq`` (GENESIS_HASH for seq 0), None when it is missing."""
    if seq == 0:
        return GENESIS_HASH
    found = conn.execute(select(events.c.hash).where(events.c.seq == seq)).scalar()
    return None if found is None else str(found)


def last_seq_recorded_by(conn: Connection, recorded_at_ns: int) -> int:
    """Length of the longest log prefix whose records were all recorded at or before a time."""
    first_later = conn.execute(
        select(func.min(events.c.seq)).where(events.c.recorded_at_ns > recorded_at_ns)
    ).scalar()
    if first_later is None:
        return head(conn)[0]
    return int(first_later) - 1


def policy_at(conn: Connection, seq: int) -> PolicyChanged | None:
    """The policy_changed record at ``seq`` (the checkpoint names it), None for seq 0."""
    if seq <= 0:
        return None
    row = conn.execute(select(events).where(events.c.seq == seq)).first()
    event = None if row is None else _to_record(row).event
    if not isinstance(event, PolicyChanged):
        raise UnknownRecordError(f"record {seq} named as the policy in force is not a policy")
    return event


@dataclass(frozen=True, slots=True)
class ChainCheck:
    """Result of walking the hash chain: how far it is intact and the first problem found."""

    records: int
    head_seq: int
    head_hash: str
    first_bad_seq: int | None
    problem: str | None


def check_chain(conn: Connection, from_seq: int = 1, to_seq: int | None = None) -> ChainCheck:
    """Recompute every hash in seq order: edits, deletions, insertions and reorders show up.

    A segment [from_seq, to_seq] starts from the stored hash of record ``from_seq - 1`` and
    must reach ``to_seq``; records outside it are not read (beyond that one hash).
    """
    prev_seq, prev_hash, count = from_seq - 1, GENESIS_HASH, 0
    if from_seq > 1:
        anchor = hash_at(conn, prev_seq)
        if anchor is None:
            return ChainCheck(0, prev_seq, "", *_missing(conn, prev_seq, prev_seq))
        prev_hash = anchor
    walked = walk_chain(_rows(conn, prev_seq, to_seq), prev_seq, prev_hash)
    if walked.problem is not None:
        return ChainCheck(*walked)
    count, prev_seq, prev_hash = walked.records, walked.head_seq, walked.head_hash
    # A segment must reach its end; an open one that starts after seq 1 must hold a record.
    last_needed = to_seq if to_seq is not None else (from_seq if from_seq > 1 else 0)
    if prev_seq < last_needed:
        first_bad, problem = _missing(conn, prev_seq + 1, last_needed)
        return ChainCheck(count, prev_seq, prev_hash, first_bad, problem)
    return ChainCheck(count, prev_seq, prev_hash, None, None)


def _missing(conn: Connection, seq: int, last_needed: int) -> tuple[int, str]:
    """First bad seq and the problem when record ``seq``, which a check up to ``last_needed``
    reads, is not stored: a hole in the log, or a log that ends too early."""
    following = conn.execute(select(func.min(events.c.seq)).where(events.c.seq > seq)).scalar()
    if following is None:
        head_seq = head(conn)[0]
        return head_seq + 1, (f"the log ends at seq {head_seq}, before record {last_needed} "
                              "that the range needs: records were deleted or never written")
    return seq, (f"record {seq} is missing (next stored record is {following}): records were "
                 "deleted or renumbered")


def codes_after(conn: Connection, seq: int, most: int, upto_seq: int | None = None
                ) -> list[str] | None:
    """Fault codes of the records after ``seq`` (up to ``upto_seq``); None when there are
    more than ``most``."""
    query = (select(events.c.fault_code).where(events.c.seq > seq,
                                               events.c.fault_code.is_not(None))
             .distinct().limit(most + 1))
    if upto_seq is not None:
        query = query.where(events.c.seq <= upto_seq)
    codes = [row[0] for row in conn.execute(query)]
    return None if len(codes) > most else codes


def read_of_codes(conn: Connection, codes: Sequence[str], upto_seq: int | None = None
                  ) -> Iterator[LogRecord]:
    """Every record of these fault codes plus every policy change, in seq order: all a
    replay of just these faults needs (faults do not affect one another). No codes: only
    the policy changes."""
    query = (select(events).where(events.c.fault_code.in_(list(codes))
                                  | (events.c.kind == POLICY_CHANGED))
             .order_by(events.c.seq))
    if upto_seq is not None:
        query = query.where(events.c.seq <= upto_seq)
    for row in stream_rows(conn, query):
        yield _to_record(row)
