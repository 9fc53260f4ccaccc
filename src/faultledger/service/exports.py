"""The audit export formats (CSV, JSON Lines), shared by `faultledger history` and
``GET /api/v1/history``: every stored column and hash, so the chain can be recomputed from an
export alone, and the log's identity on every record, so a row names its robot and log
wherever it ends up (docs/operations.md, "Export formats")."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import fields
from typing import Any, NamedTuple, TextIO

from faultledger.domain.clock import iso_ns
from faultledger.domain.identity import LedgerIdentity
from faultledger.domain.stat_rows import StatsRow
from faultledger.store.event_log import StoredRecord

EXPORT_COLUMNS = ("seq", "event_id", "kind", "fault_code", "source_id", "occurred_at",
                  "occurred_at_ns", "recorded_at", "recorded_at_ns", "schema_version",
                  "payload", "prev_hash", "hash", "robot_id", "ledger_id")
"""Export columns, in order (docs/operations.md, "Export formats")."""


def export_row(record: StoredRecord, identity: LedgerIdentity | None = None
               ) -> dict[str, Any]:
    """One record as an export object; ``payload`` is the stored canonical JSON, parsed.
    ``robot_id``/``ledger_id`` are the log's (None before it records an identity): not
    stored in the row, so not covered by its hash."""
    return {
        "seq": record.seq,
        "event_id": record.event_id,
        "kind": record.kind,
        "fault_code": record.fault_code,
        "source_id": record.source_id,
        "occurred_at": iso_ns(record.occurred_at_ns),
        "occurred_at_ns": record.occurred_at_ns,
        "recorded_at": iso_ns(record.recorded_at_ns),
        "recorded_at_ns": record.recorded_at_ns,
        "schema_version": record.schema_version,
        "payload": json.loads(record.payload_json),
        "prev_hash": record.prev_hash,
        "hash": record.hash,
        "robot_id": None if identity is None else identity.robot_id,
        "ledger_id": None if identity is None else identity.ledger_id,
    }


class Tagged(NamedTuple):
    """A record of one of several logs (a fleet central's export of a robot's logs), with
    that log's identity."""

    identity: LedgerIdentity
    record: StoredRecord


Rows = Iterable[StoredRecord] | Iterable[Tagged]
Writer = Callable[[Rows, TextIO, LedgerIdentity | None], int]


def _tagged(rows: Rows, identity: LedgerIdentity | None
            ) -> Iterator[tuple[LedgerIdentity | None, StoredRecord]]:
    for item in rows:
        if isinstance(item, Tagged):
            yield item.identity, item.record
        else:
            yield identity, item


def write_jsonl(rows: Rows, out: TextIO, identity: LedgerIdentity | None = None) -> int:
    count = 0
    for found, record in _tagged(rows, identity):
        out.write(json.dumps(export_row(record, found), ensure_ascii=False) + "\n")
        count += 1
    return count


def write_csv(rows: Rows, out: TextIO, identity: LedgerIdentity | None = None) -> int:
    """CSV with a header; NULL is an empty cell; payload is the stored canonical JSON text."""
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(EXPORT_COLUMNS)
    count = 0
    for found, r in _tagged(rows, identity):
        robot_id, ledger_id = found or ("", "")
        writer.writerow([r.seq, r.event_id, r.kind, r.fault_code or "", r.source_id or "",
                         iso_ns(r.occurred_at_ns), r.occurred_at_ns, iso_ns(r.recorded_at_ns),
                         r.recorded_at_ns, r.schema_version, r.payload_json,
                         r.prev_hash or "", r.hash, robot_id, ledger_id])
        count += 1
    return count


STATS_FIGURES = [f.name for f in fields(StatsRow)
                 if f.name not in ("period", "group", "complete")]
STATS_PERIOD_FIELDS = ["period", "period_name", "production_day", "start", "end"]


def stats_csv(rows: Sequence[StatsRow], group_by: Sequence[str]) -> str:
    """Every field of ``StatsRow.as_dict``; empty cells for undefined figures."""
    out = io.StringIO()
    fleet = ["complete"] if any(row.complete is not None for row in rows) else []
    writer = csv.DictWriter(out, fieldnames=[*STATS_PERIOD_FIELDS, *group_by, *STATS_FIGURES,
                                             *fleet], lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow(row.as_dict())
    return out.getvalue()
