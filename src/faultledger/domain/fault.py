"""The projected state of one fault, immutable so readers can share it across threads."""

from __future__ import annotations

from datetime import datetime
from typing import NamedTuple

from faultledger.domain.clock import from_ns
from faultledger.domain.types import FaultStatus, tuple_new


class Acknowledgement(NamedTuple):
    """Who acknowledged the current episode, when (the record's occurred_at), and why."""

    actor: str
    note: str
    at_ns: int
    seq: int


class Shelving(NamedTuple):
    """Who shelved the fault, why, from when until when (``until_ns``: expiry)."""

    actor: str
    reason: str
    at_ns: int
    until_ns: int
    seq: int


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
    first_ever_ns: int = 0
    """The first FAILED ever; ``first_occurred`` is the start of the current episode (it
    moves on reactivation, as medkit's does)."""
    episode_failures: int = 0
    """FAILED reports in the current episode (creation or reactivation up to now)."""
    total_failures: int = 0
    """FAILED reports ever, over all episodes."""
    confirmed_ns: int = 0
    """When the current episode first became CONFIRMED (0: not yet): the start of MTTA."""
    acknowledged: Acknowledgement | None = None
    """The current episode's first acknowledgement; None: unacknowledged."""
    shelved: Shelving | None = None
    """The shelving in force (or expired but not yet ended by a record: ``is_shelved``)."""

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

    @property
    def episode(self) -> int:
        """Episode number: 1 on creation, +1 on each reactivation from CLEARED."""
        return self.occurrence_count

    def is_shelved(self, now_ns: int) -> bool:
        """Shelved and not yet expired at ``now_ns``. An expired shelving is over even before
        the serving process records its end (a stopped server records it when it starts)."""
        return self.shelved is not None and now_ns < self.shelved.until_ns


def new_fault(
    fault_code: str,
    severity: int,
    description: str,
    first_occurred_ns: int,
    last_occurred_ns: int,
    last_passed_ns: int,
    occurrence_count: int,
    status: FaultStatus,
    reporting_sources: tuple[str, ...],
    debounce_counter: int,
    last_report_failed: bool = False,
    first_ever_ns: int = 0,
    episode_failures: int = 0,
    total_failures: int = 0,
    confirmed_ns: int = 0,
    acknowledged: Acknowledgement | None = None,
    shelved: Shelving | None = None,
) -> Fault:
    """``Fault(...)`` for the state machine, which makes one per report: the same tuple,
    without the interpreted ``__new__`` a NamedTuple runs for a call by keyword (0.78 µs;
    this, compiled, takes its keywords for free: 0.11 µs; docs/performance.md, "Eighth
    round"). Its parameters are Fault's fields, defaults included (tests/test_fault.py)."""
    fault: Fault = tuple_new(Fault, (
        fault_code, severity, description, first_occurred_ns, last_occurred_ns, last_passed_ns,
        occurrence_count, status, reporting_sources, debounce_counter, last_report_failed,
        first_ever_ns, episode_failures, total_failures, confirmed_ns, acknowledged, shelved))
    return fault
