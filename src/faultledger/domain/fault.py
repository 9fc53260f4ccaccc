"""The projected state of one fault, immutable so readers can share it across threads."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from faultledger.domain.clock import from_ns
from faultledger.domain.types import FaultStatus


@dataclass(frozen=True, slots=True)
class Fault:
    """One fault per fault_code, aggregated over all sources (SPEC §4).

    Times are kept as integer nanoseconds (the log's unit); the datetime properties are the
    public view. ``last_passed_ns == 0`` means never. ``last_report_failed`` remembers whether
    the previous accepted report was FAILED, which defines activation edges for statistics.
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
