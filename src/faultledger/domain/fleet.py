"""What a central accepts from a robot: records of one log, verbatim, whose hashes check.

Pure rules, no database: the shape of a pushed record, its hash recomputed from its own
fields, the chain inside a batch, and whether a record agrees with the robot's identity.
Where the batch meets what the central already holds is service/fleet.py's job.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from faultledger.domain.events import KINDS, LEDGER_IDENTIFIED, SCHEMA_VERSION
from faultledger.domain.integrity import record_hash
from faultledger.domain.validation import MAX_INTEGER, robot_id_error, shown

__all__ = ["MAX_BATCH_RECORDS", "BatchError", "PushedRecord", "check_batch", "ledger_id_error",
           "parse_record", "robot_id_error"]

MAX_BATCH_RECORDS = 1_000
"""Records one push may carry (docs/fleet.md)."""
_HASH = re.compile(r"^[0-9a-f]{64}$")
_UUID = re.compile(r"^[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$")


@dataclass(frozen=True, slots=True)
class PushedRecord:
    """One record exactly as the robot stores it, with its predecessor's hash."""

    seq: int
    event_id: str
    kind: str
    fault_code: str | None
    source_id: str | None
    payload: str
    occurred_at_ns: int
    recorded_at_ns: int
    schema_version: int
    hash: str
    prev_hash: str

    def computed_hash(self) -> str:
        return record_hash(self.prev_hash, self.seq, self.event_id, self.kind, self.fault_code,
                           self.source_id, self.payload, self.occurred_at_ns,
                           self.recorded_at_ns, self.schema_version)


class BatchError(ValueError):
    """A batch the central refuses; ``code`` is the answer's ``error`` (docs/fleet.md)."""

    def __init__(self, code: str, message: str, seq: int | None = None,
                 last_seq: int | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.seq = seq
        self.last_seq = last_seq


def ledger_id_error(ledger_id: object) -> str | None:
    if not isinstance(ledger_id, str) or not _UUID.match(ledger_id):
        return f"ledger_id must be a lowercase UUID, got {shown(ledger_id)}"
    return None


_FIELDS: tuple[tuple[str, tuple[type, ...], bool], ...] = (
    ("seq", (int,), False), ("event_id", (str,), False), ("kind", (str,), False),
    ("fault_code", (str,), True), ("source_id", (str,), True), ("payload", (str,), False),
    ("occurred_at_ns", (int,), False), ("recorded_at_ns", (int,), False),
    ("schema_version", (int,), False), ("hash", (str,), False), ("prev_hash", (str,), False),
)


def parse_record(raw: object, position: int) -> PushedRecord:
    """One element of ``records`` as a PushedRecord, or BatchError naming what is wrong.

    A well-formed record takes the fast path (one type test per field: a central checks tens
    of thousands a second); anything else is examined field by field for the message."""
    if type(raw) is dict and len(raw) == len(_FIELDS):
        get = raw.get
        seq, event_id, kind, code, source, payload, occurred, recorded, version, digest, prev = (
            get("seq"), get("event_id"), get("kind"), get("fault_code"), get("source_id"),
            get("payload"), get("occurred_at_ns"), get("recorded_at_ns"),
            get("schema_version"), get("hash"), get("prev_hash"))
        if (type(seq) is int and type(occurred) is int and type(recorded) is int
                and type(version) is int and type(event_id) is str and type(kind) is str
                and type(payload) is str and type(digest) is str and type(prev) is str
                and (code is None or type(code) is str) and (source is None or type(source) is str)
                and 1 <= seq <= MAX_INTEGER and 0 <= occurred <= MAX_INTEGER
                and 0 <= recorded <= MAX_INTEGER and 0 <= version <= MAX_INTEGER
                and len(digest) == 64 and len(prev) == 64):
            # A hash that is not hex cannot equal the one recomputed (check_batch), and a
            # prev_hash that is not must still equal the hash before it: no regex needed here.
            return PushedRecord(seq, event_id, kind, code, source, payload, occurred, recorded,
                                version, digest, prev)
    return _parse_slowly(raw, position)


def _parse_slowly(raw: object, position: int) -> PushedRecord:
    where = f"record {position}"
    if not isinstance(raw, Mapping):
        raise BatchError("invalid-request", f"{where} must be a JSON object, got {shown(raw)}")
    unknown = sorted(set(raw) - {name for name, _, _ in _FIELDS})
    if unknown:
        raise BatchError("invalid-request", f"{where}: unknown field {shown(unknown[0])}")
    values: dict[str, Any] = {}
    for name, types, nullable in _FIELDS:
        if name not in raw:
            raise BatchError("invalid-request", f"{where}: {name} is required")
        value = raw[name]
        if value is None and nullable:
            values[name] = None
            continue
        if isinstance(value, bool) or not isinstance(value, types):
            raise BatchError("invalid-request", f"{where}: {name} must be "
                             f"{'an integer' if types == (int,) else 'text'}, got {shown(value)}")
        if isinstance(value, int) and not 0 <= value <= MAX_INTEGER:
            raise BatchError("invalid-request", f"{where}: {name} is out of range")
        values[name] = value
    for name in ("hash", "prev_hash"):
        if not _HASH.match(values[name]):
            raise BatchError("invalid-request", f"{where}: {name} must be 64 lowercase hex "
                             "digits")
    if values["seq"] < 1:
        raise BatchError("invalid-request", f"{where}: seq must be 1 or more")
    return PushedRecord(**values)


def check_batch(records: Sequence[PushedRecord], robot_id: str, ledger_id: str) -> None:
    """Consecutive seqs, every hash recomputed, each record chained to the one before, and
    an identity record (if the batch holds one) naming this robot and log; BatchError
    naming the first seq that fails."""
    if len(records) > MAX_BATCH_RECORDS:
        raise BatchError("invalid-request", f"{len(records)} records in one batch; at most "
                         f"{MAX_BATCH_RECORDS}")
    previous: PushedRecord | None = None
    for record in records:
        if previous is not None:
            if record.seq != previous.seq + 1:
                raise BatchError("invalid-request", f"records must be consecutive: seq "
                                 f"{record.seq} follows {previous.seq}", record.seq)
            if record.prev_hash != previous.hash:
                raise BatchError("broken-chain", f"record {record.seq}: prev_hash is not the "
                                 f"hash of record {previous.seq}", record.seq)
        if record.computed_hash() != record.hash:
            raise BatchError("broken-chain", f"record {record.seq} does not match its hash: it "
                             "was edited after it was written", record.seq)
        _check_readable(record)
        if record.kind == LEDGER_IDENTIFIED:
            payload = json.loads(record.payload)
            if payload.get("robot_id") != robot_id or payload.get("ledger_id") != ledger_id:
                raise BatchError("robot-differs", f"record {record.seq} identifies the log as "
                                 f"robot {shown(payload.get('robot_id'))}, ledger "
                                 f"{shown(payload.get('ledger_id'))}, not {robot_id}, "
                                 f"{ledger_id}", record.seq)
        previous = record


def _check_readable(record: PushedRecord) -> None:
    """The central projects what it stores: a kind or schema version it does not know is
    refused now (the hash already proves the payload is what the robot wrote and read)."""
    if record.kind not in KINDS or record.schema_version > SCHEMA_VERSION:
        raise BatchError("unreadable-record", f"record {record.seq} is of kind "
                         f"{shown(record.kind, 40)} version {record.schema_version}, which this "
                         "central does not know: upgrade the central first", record.seq)
