"""The debounce state machine of SPEC §4.2-4.3: the one place a fault status is computed."""

from __future__ import annotations

from faultledger.domain.events import FaultReported
from faultledger.domain.fault import Fault, new_fault
from faultledger.domain.policy import DebounceParams, Policy
from faultledger.domain.types import EventType, FaultStatus, Severity

_LATCHED = (FaultStatus.CONFIRMED, FaultStatus.HEALED)


def clamp(counter: int, params: DebounceParams) -> int:
    return max(params.confirmation_threshold, min(counter, params.healing_threshold))


def status(counter: int, current: FaultStatus, params: DebounceParams) -> FaultStatus:
    if counter <= params.confirmation_threshold:
        return FaultStatus.CONFIRMED
    if params.healing_enabled and counter >= params.healing_threshold:
        return FaultStatus.HEALED
    if current in _LATCHED:
        return current
    if counter < 0:
        return FaultStatus.PREFAILED
    if counter > 0:
        return FaultStatus.PREPASSED
    return current


def _failed_status(counter: int, current: FaultStatus, report: FaultReported,
                   params: DebounceParams) -> FaultStatus:
    if report.severity == Severity.CRITICAL:
        return FaultStatus.CONFIRMED
    return status(counter, current, params)


def _sources(fault: Fault, source_id: str) -> tuple[str, ...]:
    if source_id in fault.reporting_sources:
        return fault.reporting_sources
    return tuple(sorted((*fault.reporting_sources, source_id)))


def apply_report(
    fault: Fault | None, report: FaultReported, params: DebounceParams, at_ns: int
) -> Fault | None:
    """State after one report; returns ``fault`` itself when the report changes nothing."""
    failed = report.event_type is EventType.FAILED
    if fault is None:
        if not failed:
            return None
        return new_fault(
            fault_code=report.fault_code,
            severity=report.severity,
            description=report.description,
            first_occurred_ns=at_ns,
            last_occurred_ns=at_ns,
            last_passed_ns=0,
            occurrence_count=1,
            status=_failed_status(-1, FaultStatus.PREFAILED, report, params),
            reporting_sources=(report.source_id,),
            debounce_counter=-1,
            last_report_failed=True,
            first_ever_ns=at_ns,
            episode_failures=1,
            total_failures=1,
        )
    if fault.status is FaultStatus.CLEARED:
        if not failed:
            return fault
        return new_fault(
            fault_code=fault.fault_code,
            severity=max(fault.severity, report.severity),
            description=report.description or fault.description,
            first_occurred_ns=at_ns,
            last_occurred_ns=at_ns,
            last_passed_ns=fault.last_passed_ns,
            occurrence_count=fault.occurrence_count + 1,
            status=_failed_status(-1, FaultStatus.PREFAILED, report, params),
            reporting_sources=_sources(fault, report.source_id),
            debounce_counter=-1,
            last_report_failed=True,
            first_ever_ns=fault.first_ever_ns,
            episode_failures=1,
            total_failures=fault.total_failures + 1,
            shelved=fault.shelved,  # a new episode: a new acknowledgement, the same shelving
        )
    if failed:
        counter = clamp(clamp(fault.debounce_counter, params) - 1, params)
        return new_fault(
            fault_code=fault.fault_code,
            severity=max(fault.severity, report.severity),
            description=report.description or fault.description,
            first_occurred_ns=fault.first_occurred_ns,
            last_occurred_ns=at_ns,
            last_passed_ns=fault.last_passed_ns,
            occurrence_count=fault.occurrence_count,
            status=_failed_status(counter, fault.status, report, params),
            reporting_sources=_sources(fault, report.source_id),
            debounce_counter=counter,
            last_report_failed=True,
            first_ever_ns=fault.first_ever_ns,
            episode_failures=fault.episode_failures + 1,
            total_failures=fault.total_failures + 1,
            confirmed_ns=fault.confirmed_ns,
            acknowledged=fault.acknowledged,
            shelved=fault.shelved,
        )
    counter = clamp(clamp(fault.debounce_counter, params) + 1, params)
    return new_fault(
        fault_code=fault.fault_code,
        severity=fault.severity,
        description=fault.description,
        first_occurred_ns=fault.first_occurred_ns,
        last_occurred_ns=fault.last_occurred_ns,
        last_passed_ns=at_ns,
        occurrence_count=fault.occurrence_count,
        status=status(counter, fault.status, params),
        reporting_sources=fault.reporting_sources,
        debounce_counter=counter,
        last_report_failed=False,
        first_ever_ns=fault.first_ever_ns,
        episode_failures=fault.episode_failures,
        total_failures=fault.total_failures,
        confirmed_ns=fault.confirmed_ns,
        acknowledged=fault.acknowledged,
        shelved=fault.shelved,
    )


def is_overdue(fault: Fault, after_sec: float, now_ns: int) -> bool:
    """Time-based confirmation: PREFAILED and the last FAILED is at least ``after_sec`` old."""
    return (
        after_sec > 0
        and fault.status is FaultStatus.PREFAILED
        and now_ns - fault.last_occurred_ns >= round(after_sec * 1e9)
    )


def heals_under(fault: Fault, policy: Policy) -> bool:
    """Whether healing is enabled for any source that reported this fault."""
    return any(policy.resolve(source, fault.fault_code).healing_enabled
               for source in fault.reporting_sources)


def reclassify_on_startup(fault: Fault, policy: Policy) -> bool:
    """A HEALED fault becomes CLEARED at startup when no policy in force can heal it."""
    return fault.status is FaultStatus.HEALED and not heals_under(fault, policy)


def is_ignored(fault: Fault | None, report: FaultReported) -> bool:
    """PASSED for no fault, or for a CLEARED one: logged, but it changes no fault (SPEC §4.2)."""
    return report.event_type is EventType.PASSED and (
        fault is None or fault.status is FaultStatus.CLEARED
    )
