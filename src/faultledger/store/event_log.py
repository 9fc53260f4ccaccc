"""The append-only event log: append, read in seq order, query, and check the hash chain."""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Connection, Integer, bindparam, func, select

from faultledger.domain.events import LogRecord, PolicyChanged, UnknownRecordError, decode
from faultledger.domain.integrity import GENESIS_HASH, canonical_json, record_hash
from faultledger.store import fastpath
from faultledger.store.schema import events

READ_CHUNK = 5_000


_HEAD = select(events.c.seq, events.c.hash).order_by(events.c.seq.desc()).limit(1)
_INSERT = events.insert()


def head(conn: Connection) -> tuple[int, str]:
    """Seq and hash of the newest record, (0, GENESIS_HASH) for an empty log."""
    row = fastpath.fetch_one(conn, _HEAD)
    return (0, GENESIS_HASH) if row is None else (int(row[0]), str(row[1]))


def existing_event_ids(conn: Connection, event_ids: Sequence[str]) -> set[str]:
    if not event_ids:
        return set()
    found = conn.execute(select(events.c.event_id).where(events.c.event_id.in_(event_ids)))
    return {str(r[0]) for r in found}


def append(conn: Connection, records: Sequence[LogRecord], prev_hash: str) -> str:
    """Insert records (seq already assigned, gap-free) chaining their hashes; returns the last."""
    rows: list[dict[str, Any]] = []
    for record in records:
        payload_json = canonical_json(record.payload)
        prev_hash = record_hash(
            prev_hash, record.seq, record.event_id, record.kind, record.fault_code,
            record.source_id, payload_json, record.occurred_at_ns, record.recorded_at_ns,
            record.schema_version,
        )
        rows.append({
            "seq": record.seq,
            "event_id": record.event_id,
            "kind": record.kind,
            "fault_code": record.fault_code,
            "source_id": record.source_id,
            "payload": payload_json,
            "occurred_at_ns": record.occurred_at_ns,
            "recorded_at_ns": record.recorded_at_ns,
            "schema_version": record.schema_version,
            "hash": prev_hash,
        })
    fastpath.execute_many(conn, _INSERT, rows)
    return prev_hash


_raw_decode = json.JSONDecoder().raw_decode  # payloads are canonical: no whitespace to skip


def _to_record(row: Sequence[Any]) -> LogRecord:
    """A stored row (columns in table order) as a LogRecord; positional for replay speed."""
    seq, event_id, kind, _code, _source, payload, occurred, recorded, version, digest = row
    return LogRecord(seq, event_id, decode(kind, version, _raw_decode(payload)[0]), occurred,
                     recorded, version, digest)


_AFTER = bindparam("after", type_=Integer)
_UPTO = bindparam("upto", type_=Integer)
_CHUNK = bindparam("chunk", type_=Integer)
_PAGE = select(events).where(events.c.seq > _AFTER).order_by(events.c.seq).limit(_CHUNK)
_PAGE_UPTO = (select(events).where(events.c.seq > _AFTER, events.c.seq <= _UPTO)
              .order_by(events.c.seq).limit(_CHUNK))


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


@dataclass(frozen=True, slots=True)
class RecordFilter:
    fault_code: str | None = None
    source_id: str | None = None
    since_ns: int | None = None
    until_ns: int | None = None
    kinds: tuple[str, ...] = ()
    limit: int | None = None


def find(conn: Connection, where: RecordFilter) -> list[LogRecord]:
    """Records matching every given filter; times compare with ``occurred_at`` in [since, until)."""
    query = select(events).order_by(events.c.seq)
    if where.fault_code is not None:
        query = query.where(events.c.fault_code == where.fault_code)
    if where.source_id is not None:
        query = query.where(events.c.source_id == where.source_id)
    if where.since_ns is not None:
        query = query.where(events.c.occurred_at_ns >= where.since_ns)
    if where.until_ns is not None:
        query = query.where(events.c.occurred_at_ns < where.until_ns)
    if where.kinds:
        query = query.where(events.c.kind.in_(where.kinds))
    if where.limit is not None:
        query = query.limit(where.limit)
    return [_to_record(row) for row in conn.execute(query)]


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


def check_chain(conn: Connection) -> ChainCheck:
    """Recompute every hash in seq order: edits, deletions, insertions and reorders show up."""
    prev_seq, prev_hash, count = 0, GENESIS_HASH, 0
    for row in _rows(conn):
        seq, event_id, kind, code, source, payload, occurred, recorded, version, digest = row
        count += 1
        if seq != prev_seq + 1:
            return ChainCheck(count, prev_seq, prev_hash, prev_seq + 1,
                              f"record {prev_seq + 1} is missing (next stored record is "
                              f"{seq}): records were deleted or renumbered")
        expected = record_hash(prev_hash, seq, event_id, kind, code, source, payload, occurred,
                               recorded, version)
        if expected != digest:
            return ChainCheck(count, prev_seq, prev_hash, seq,
                              f"record {seq} does not match its hash: it was edited, "
                              "inserted or moved")
        prev_seq, prev_hash = seq, digest
    return ChainCheck(count, prev_seq, prev_hash, None, None)
