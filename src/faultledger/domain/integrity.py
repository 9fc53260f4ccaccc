"""The hash chain of SPEC §3: hash = sha256(prev_hash || canonical(record))."""

from __future__ import annotations

import hashlib
import json
from typing import Any

GENESIS_HASH = "0" * 64
"""The ``prev_hash`` of record 1."""


_CANONICAL = json.JSONEncoder(sort_keys=True, separators=(",", ":"), ensure_ascii=False,
                              allow_nan=False)


def canonical_json(value: Any) -> str:
    """Sorted keys, no spaces, UTF-8 text: one byte string per value, on every machine."""
    return _CANONICAL.encode(value)


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
    """Chain hash over every stored column of a record (documented in docs/operations.md)."""
    canonical = canonical_json(
        [seq, event_id, kind, fault_code, source_id, occurred_at_ns, recorded_at_ns,
         schema_version]
    )
    digest = hashlib.sha256(prev_hash.encode("ascii"))
    digest.update(canonical.encode("utf-8"))
    digest.update(payload_json.encode("utf-8"))
    return digest.hexdigest()
