"""The projected state of one fault, immutable so readers can share it across threads."""

from __future__ import annotations

from datetime import datetime
from typing import NamedTuple

from faultledger.domain.clock import from_ns
from faultledger.domain.types import FaultStatus


class Fault(NamedTuple):
    """One fault per fault_code, aggregated over all sources (SPEC §4).

    Times are kept as integer nanoseconds (the log's unit); the datetime properties are the
    public view. ``last_passed_ns == 0`` means never. ``last_report_failed`` remembers whether
    the previous accepted report was FAILED, which defines activation edges for statistics.
    A NamedTuple: immutable like a frozen dataclass, but three times cheaper to create, which
    matters when a replay creates one per record.
    """

    fault_code: str
    severity: int
    description: str
    first_occurred_ns: int
    last_occurred_ns: int
    last_passed_ns: int
    occurrence_count: int
    status: FaultStatus
    reporting_sources: tuple[str, ...]
    debounce_counter: int
    last_report_failed: bool = False

    @property
    def first_occurred(self) -> datetime:
        return from_ns(self.first_occurred_ns)

    @property
    def last_occurred(self) -> datetime:
        return from_ns(self.last_occurred_ns)

    @property
    def last_passed(self) -> datetime | None:
        return from_ns(self.last_passed_ns) if self.last_passed_ns else None

    @property
    def is_active(self) -> bool:
        return self.status is not FaultStatus.CLEARED
