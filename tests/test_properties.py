"""Property tests: the state machine's invariants and "restart == full replay" (SPEC §4, §5)."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faultledger import Fault, FaultLedger, FaultStatus, Policy
from faultledger.domain.debounce import apply_report
from faultledger.domain.events import FaultReported
from faultledger.domain.types import EventType

T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)
CODES = ("MOTOR_OVERHEAT", "LIDAR_TIMEOUT", "HW_ARM_EMERGENCY_STOP")
SOURCES = ("/motor", "/sensors/lidar", "/sensors/lidar/front", "/sensors/lid", "/arm")

policies = st.builds(
    Policy,
    confirmation_threshold=st.integers(-4, 2),
    healing_enabled=st.booleans(),
    healing_threshold=st.integers(-2, 4),
    auto_confirm_after_sec=st.sampled_from([0.0, 5.0]),
    overrides=st.sampled_from([
        {},
        {"/sensors/lidar": {"confirmation_threshold": -1, "healing_enabled": True}},
        {"/sensors": {"healing_threshold": 1}, "/arm": {"confirmation_threshold": -2}},
    ]),
)


@dataclass(frozen=True)
class Report:
    code: str
    event_type: str
    severity: int
    source: str
    seconds: int


@dataclass(frozen=True)
class Clear:
    code: str
    seconds: int


@dataclass(frozen=True)
class Timer:
    seconds: int


@dataclass(frozen=True)
class Operator:
    """An acknowledgement, shelving (for ``duration`` seconds) or unshelving."""

    action: str
    code: str
    seconds: int
    duration: int = 0


@dataclass(frozen=True)
class Reopen:
    pass


Op = Report | Clear | Timer | Operator | Reopen

reports = st.builds(Report, st.sampled_from(CODES), st.sampled_from(["FAILED", "PASSED"]),
                    st.integers(0, 3), st.sampled_from(SOURCES), st.integers(0, 20))
operations = st.lists(
    st.one_of(
        reports, reports, reports,
        st.builds(Clear, st.sampled_from(CODES), st.integers(0, 20)),
        st.builds(Timer, st.integers(0, 20)),
        st.builds(Operator, st.sampled_from(["ack", "shelve", "unshelve"]),
                  st.sampled_from(CODES), st.integers(0, 20), st.integers(1, 10)),
        st.just(Reopen()),
    ),
    max_size=40,
)

_files = itertools.count()


def _db(fresh_url: Callable[[str], str]) -> str:
    """A fresh log per example (fixtures are per test, examples are many)."""
    return fresh_url(f"p{next(_files)}")


def _drive(ledger: FaultLedger, op: Report | Clear | Timer | Operator, now: datetime) -> None:
    if isinstance(op, Report):
        result = ledger.report(op.code, op.event_type, op.severity, "", op.source, at=now)
        assert result.accepted, result.message
    elif isinstance(op, Clear):
        ledger.clear(op.code, actor="test", at=now)
    elif isinstance(op, Operator):
        if op.action == "ack":
            ledger.acknowledge(op.code, "test", at=now)
        elif op.action == "shelve":
            ledger.shelve(op.code, op.duration, "test", at=now)
        else:
            ledger.unshelve(op.code, "test", at=now)
    else:
        ledger.run_timers(now)


def _state(ledger: FaultLedger) -> list[Fault]:
    return ledger.all_faults()


DB_SETTINGS = settings(max_examples=25, deadline=None,
                       suppress_health_check=[HealthCheck.function_scoped_fixture])


@DB_SETTINGS
@given(policy=policies, ops=operations)
def test_reopening_restores_exactly_the_state_before_closing(
    fresh_url: Callable[[str], str], policy: Policy, ops: list[Op]
) -> None:
    url = _db(fresh_url)
    now = T0
    ledger = FaultLedger.open(url, policy=policy, background=False)
    try:
        for op in ops:
            if isinstance(op, Reopen):
                before = _state(ledger)
                ledger.close()
                ledger = FaultLedger.open(url, policy=policy, background=False)
                assert _state(ledger) == before
                continue
            now += timedelta(seconds=op.seconds)
            _drive(ledger, op, now)
        before = _state(ledger)
    finally:
        ledger.close()
    with FaultLedger.open(url) as reopened:
        assert _state(reopened) == before


@DB_SETTINGS
@given(policy=policies, ops=operations)
def test_incremental_projection_equals_full_replay(
    fresh_url: Callable[[str], str], policy: Policy, ops: list[Op]
) -> None:
    now = T0
    with FaultLedger.open(_db(fresh_url), policy=policy, background=False) as ledger:
        for op in ops:
            if not isinstance(op, Reopen):
                now += timedelta(seconds=op.seconds)
                _drive(ledger, op, now)
        incremental = _state(ledger)
        incremental_transitions = ledger.transitions()
        assert ledger.state_at(ledger.last_seq) == incremental
        assert ledger.verify().ok
        ledger.rebuild()
        assert _state(ledger) == incremental
        assert ledger.transitions() == incremental_transitions


@DB_SETTINGS
@given(policy=policies, ops=operations, data=st.data())
def test_state_at_seq_equals_replay_of_the_first_n_records(
    fresh_url: Callable[[str], str], policy: Policy,
    ops: list[Op], data: st.DataObject
) -> None:
    now = T0
    snapshots: dict[int, list[Fault]] = {}
    with FaultLedger.open(_db(fresh_url), policy=policy, background=False) as ledger:
        snapshots[ledger.last_seq] = _state(ledger)
        for op in ops:
            if not isinstance(op, Reopen):
                now += timedelta(seconds=op.seconds)
                _drive(ledger, op, now)
                snapshots[ledger.last_seq] = _state(ledger)
        seq = data.draw(st.sampled_from(sorted(snapshots)))
        assert ledger.state_at(seq) == snapshots[seq]


# -- the pure state machine --------------------------------------------------------------------

report_events = st.builds(
    FaultReported,
    fault_code=st.just("F"),
    event_type=st.sampled_from(EventType),
    severity=st.integers(0, 3),
    description=st.sampled_from(["", "hot"]),
    source_id=st.sampled_from(SOURCES),
)


@settings(max_examples=300)
@given(policy=policies, events=st.lists(report_events, max_size=60))
def test_state_machine_invariants_hold_for_any_report_sequence(
    policy: Policy, events: list[FaultReported]
) -> None:
    fault: Fault | None = None
    for i, event in enumerate(events):
        params = policy.resolve(event.source_id)
        before = fault
        fault = apply_report(fault, event, params, i + 1)
        if fault is None:
            assert before is None and event.event_type is EventType.PASSED
            continue
        assert params.confirmation_threshold <= fault.debounce_counter <= max(
            params.healing_threshold, params.confirmation_threshold)
        assert list(fault.reporting_sources) == sorted(set(fault.reporting_sources))
        if before is None:
            continue
        assert fault.severity >= before.severity
        assert set(before.reporting_sources) <= set(fault.reporting_sources)
        reactivated = before.status is FaultStatus.CLEARED and fault.status is not (
            FaultStatus.CLEARED)
        assert fault.occurrence_count == before.occurrence_count + (1 if reactivated else 0)
        if before.status is FaultStatus.CONFIRMED:
            assert fault.status in (FaultStatus.CONFIRMED, FaultStatus.HEALED)
        if event.event_type is EventType.FAILED and event.severity == 3:
            assert fault.status is FaultStatus.CONFIRMED


@settings(max_examples=200)
@given(policy=policies, events=st.lists(report_events, max_size=40))
def test_state_machine_is_deterministic(policy: Policy, events: list[FaultReported]) -> None:
    def run() -> Fault | None:
        fault: Fault | None = None
        for i, event in enumerate(events):
            fault = apply_report(fault, event, policy.resolve(event.source_id), i)
        return fault

    assert run() == run()
