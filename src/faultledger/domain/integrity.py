"""The hash chain of SPEC §3: hash = sha256(prev_hash || canonical(record))."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Sequence
from json.encoder import encode_basestring
from typing import Any, NamedTuple

import msgspec

from faultledger.domain.events import DomainEvent, FaultReported
from faultledger.domain.types import EVENT_TYPE_NAMES

GENESIS_HASH = "0" * 64
"""The ``prev_hash`` of record 1."""


_CANONICAL = json.JSONEncoder(sort_keys=True, separators=(",", ":"), ensure_ascii=False,
                              allow_nan=False)


_string = encode_basestring  # what _CANONICAL writes for a str (ensure_ascii=False)


def canonical_json(value: Any) -> str:
    """Sorted keys, no spaces, UTF-8 text: one byte string per value, on every machine."""
    return _CANONICAL.encode(value)


_fast_decode = msgspec.json.Decoder().decode


def parse_json(text: str | bytes) -> Any:
    """The value of a JSON text, exactly as ``json.loads`` reads it, in a quarter of the time
    (msgspec's decoder: 0.47 against 1.8 µs for a report's payload; a rebuild reads a
    million). What msgspec refuses and ``json`` reads (``NaN``, a lone surrogate, a float
    out of range: none of them written by ``canonical_json``) is read by ``json``, so a
    text reads the same either way (tests/test_integrity.py)."""
    try:
        return _fast_decode(text)
    except msgspec.MsgspecError:
        return json.loads(text)


def payload_json(event: DomainEvent) -> str:
    """The canonical JSON of a record's payload (``canonical_json(event.payload())``).

    A fault report, nine records in ten, is written out by hand: the encoder's dict walk
    cost a fifth of the append's Python. tests/test_integrity.py holds both to the same
    bytes for any text."""
    if isinstance(event, FaultReported) and type(event.severity) is int:
        return (f'{{"description":{_string(event.description)},'
                f'"event_type":"{EVENT_TYPE_NAMES[event.event_type]}",'
                f'"fault_code":{_string(event.fault_code)},"severity":{event.severity},'
                f'"source_id":{_string(event.source_id)}}}')
    return _CANONICAL.encode(event.payload())


def record_hash(
    prev_hash: str,
    seq: int,
    event_id: str,
    kind: str,
    fault_code: str | None,
    source_id: str | None,
    payload_json: str,
    occurred_at_ns: int,
    recorded_at_ns: int,
    schema_version: int,
) -> str:
    """Chain hash over every stored column of a record (documented in docs/operations.md):
    sha256 of prev_hash, then ``canonical_json([seq, event_id, kind, fault_code, source_id,
    occurred_at_ns, recorded_at_ns, schema_version])``, then the payload's JSON text.

    The list is written out here rather than through the encoder (half the time: a central
    recomputes tens of thousands a second); ``_string`` is the encoder's own string escaping
    (ensure_ascii=False), and tests/test_integrity.py holds both to the same bytes."""
    canonical = (f"[{int(seq)},{_string(event_id)},{_string(kind)},"
                 f"{'null' if fault_code is None else _string(fault_code)},"
                 f"{'null' if source_id is None else _string(source_id)},"
                 f"{int(occurred_at_ns)},{int(recorded_at_ns)},{int(schema_version)}]")
    return hashlib.sha256(f"{prev_hash}{canonical}{payload_json}".encode()).hexdigest()


class ChainWalk(NamedTuple):
    """How far a walk of the chain got: records read, the last good (seq, hash), and the
    first bad seq with the problem (None: intact)."""

    records: int
    head_seq: int
    head_hash: str
    first_bad_seq: int | None
    problem: str | None


def walk_chain(rows: Iterable[Sequence[Any]], prev_seq: int, prev_hash: str) -> ChainWalk:
    """Recompute every hash of stored rows (seq, event_id, kind, fault_code, source_id,
    payload, occurred_at_ns, recorded_at_ns, schema_version, hash) in seq order after
    (prev_seq, prev_hash): edits, deletions, insertions and reorders show up. The one rule
    for a robot's log and for the copy a fleet central holds of it."""
    count = 0
    for row in rows:
        seq, event_id, kind, code, source, payload, occurred, recorded, version, digest = row
        count += 1
        if seq != prev_seq + 1:
            return ChainWalk(count, prev_seq, prev_hash, prev_seq + 1,
                             f"record {prev_seq + 1} is missing (next stored record is "
                             f"{seq}): records were deleted or renumbered")
        expected = record_hash(prev_hash, seq, event_id, kind, code, source, payload, occurred,
                               recorded, version)
        if expected != digest:
            return ChainWalk(count, prev_seq, prev_hash, seq,
                             f"record {seq} does not match its hash: it was edited, "
                             "inserted or moved")
        prev_seq, prev_hash = seq, digest
    return ChainWalk(count, prev_seq, prev_hash, None, None)
