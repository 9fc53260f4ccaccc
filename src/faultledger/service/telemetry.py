"""What this process's writer did, for metrics (``GET /metrics``): records appended by kind,
reports by event type, group-commit latency. Plain counters, updated once per commit under
one lock, so the service does not depend on any metrics library."""

from __future__ import annotations

import bisect
import threading
from collections.abc import Sequence
from dataclasses import dataclass

from faultledger.domain.events import FaultReported, LogRecord
from faultledger.domain.types import EVENT_TYPE_NAMES

COMMIT_BUCKETS = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5)
"""Upper bounds (seconds) of the commit latency histogram; one more bucket holds the rest."""


@dataclass(frozen=True, slots=True)
class Snapshot:
    records: dict[str, int]
    """Records appended by kind."""
    reports: dict[str, int]
    """``fault_reported`` records by event type (FAILED, PASSED)."""
    commits: int
    commit_seconds_sum: float
    commit_buckets: tuple[int, ...]
    """Commits per bucket of ``COMMIT_BUCKETS`` (not cumulative), then the overflow."""


class Telemetry:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._records: dict[str, int] = {}
        self._reports: dict[str, int] = {}
        self._commits = 0
        self._seconds = 0.0
        self._buckets = [0] * (len(COMMIT_BUCKETS) + 1)

    def committed(self, records: Sequence[LogRecord], seconds: float) -> None:
        with self._lock:  # plain dict counts: this runs once per commit on the hot path
            kinds, types = self._records, self._reports
            for record in records:
                event = record.event
                kind = event.kind
                kinds[kind] = kinds.get(kind, 0) + 1
                if isinstance(event, FaultReported):
                    name = EVENT_TYPE_NAMES[event.event_type]  # (Enum.name is slow)
                    types[name] = types.get(name, 0) + 1
            self._commits += 1
            self._seconds += seconds
            self._buckets[bisect.bisect_left(COMMIT_BUCKETS, seconds)] += 1

    def snapshot(self) -> Snapshot:
        with self._lock:
            return Snapshot(dict(self._records), dict(self._reports), self._commits,
                            self._seconds, tuple(self._buckets))
