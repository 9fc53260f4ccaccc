"""Query rules of SPEC §4.6: which faults a list or entity request returns."""

from __future__ import annotations

from collections.abc import Iterable

from faultledger.domain.fault import Fault
from faultledger.domain.types import FaultStatus

_KNOWN = frozenset(FaultStatus)


def status_filter(statuses: Iterable[str]) -> frozenset[FaultStatus]:
    """Requested statuses; empty or only unknown strings means CONFIRMED only (medkit)."""
    wanted = frozenset(FaultStatus(s) for s in map(str, statuses) if s in _KNOWN)
    return wanted or frozenset({FaultStatus.CONFIRMED})


def select(faults: Iterable[Fault], statuses: Iterable[str] = (),
           severity: int | None = None) -> list[Fault]:
    wanted = status_filter(statuses)
    return sorted(
        (f for f in faults if f.status in wanted and (severity is None or f.severity == severity)),
        key=lambda f: f.fault_code,
    )


def reported_by_entity(fault: Fault, entity_id: str) -> bool:
    suffix = "/" + entity_id
    return any(s == entity_id or s.endswith(suffix) for s in fault.reporting_sources)


def for_entity(faults: Iterable[Fault], entity_id: str) -> list[Fault]:
    return sorted((f for f in faults if reported_by_entity(f, entity_id)),
                  key=lambda f: f.fault_code)
