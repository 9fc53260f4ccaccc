"""Answers of the service API: errors are values at this boundary, not exceptions."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from faultledger.domain.fault import Fault
from faultledger.domain.identity import LedgerIdentity
from faultledger.errors import Reason


def _default_reason(result: Any, ok: bool, duplicate: bool = False) -> None:
    """Fill in the usual reason when none was given: ok, duplicate, else invalid input."""
    if not result.reason:
        reason = Reason.DUPLICATE if duplicate else Reason.OK if ok else Reason.INVALID
        object.__setattr__(result, "reason", reason)


@dataclass(frozen=True, slots=True)
class ReportResult:
    accepted: bool
    message: str
    seq: int | None = None
    event_id: str | None = None
    duplicate: bool = False
    reason: str = ""
    """A ``Reason``: ok, duplicate, invalid, unavailable or internal."""

    def __post_init__(self) -> None:
        _default_reason(self, self.accepted, self.duplicate)


@dataclass(frozen=True, slots=True)
class ClearResult:
    success: bool
    message: str
    seq: int | None = None
    reason: str = ""
    """A ``Reason``: ok, invalid, not_found, unavailable or internal."""

    def __post_init__(self) -> None:
        _default_reason(self, self.success)


@dataclass(frozen=True, slots=True)
class OperatorResult:
    """The answer to an acknowledgement, shelving or unshelving."""

    success: bool
    message: str
    seq: int | None = None
    """The record made; None when nothing was recorded (refused, or already acknowledged)."""
    reason: str = ""
    """A ``Reason``: ok, duplicate (already acknowledged), invalid, not_found, conflict,
    unavailable or internal."""
    fault: Fault | None = None
    """The fault after the action (as it was, when nothing was recorded)."""

    def __post_init__(self) -> None:
        _default_reason(self, self.success)


@dataclass(frozen=True, slots=True)
class FaultLookup:
    success: bool
    message: str
    fault: Fault | None = None
    reason: str = ""
    """A ``Reason``: ok, invalid or not_found."""

    def __post_init__(self) -> None:
        _default_reason(self, self.success)


@dataclass(frozen=True, slots=True)
class EntityLookup:
    success: bool
    message: str
    faults: list[Fault] = field(default_factory=list)
    reason: str = ""
    """A ``Reason``: ok or invalid."""

    def __post_init__(self) -> None:
        _default_reason(self, self.success)


@dataclass(frozen=True, slots=True)
class VerifyReport:
    """Outcome of ``verify``: chain intact, head anchored, projections equal a full replay."""

    ok: bool
    records: int
    head_seq: int
    head_hash: str
    first_bad_seq: int | None = None
    problems: list[str] = field(default_factory=list)
    identity: LedgerIdentity | None = None
    """The identity the log's projection records (robot_id, ledger_id); None: none yet."""


@dataclass(frozen=True, slots=True)
class Downtime:
    """One CONFIRMED episode overlapping a range (``FaultLedger.downtimes``)."""

    fault_code: str
    source_id: str
    """Source of the fact that confirmed it."""
    severity: int
    start: datetime
    end: datetime | None
    """None: still CONFIRMED at ``as_of``."""
    seconds: float
    """Whole episode; an open one counts up to ``as_of``."""
    seconds_in_range: float
    """The part inside the range."""
