"""SPEC §4.2: time-based confirmation (run_timers) and what a restart does to the fault state."""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest

from faultledger import Fault, FaultLedger, FaultStatus, LogRecord, Notification, Policy

OpenLedger = Callable[..., FaultLedger]
Subscribe = Callable[[FaultLedger], list[Notification]]

# Report times lie in the future on purpose: a ledger that also checks timers against the wall
# clock can then never confirm these faults on its own, so only run_timers(now=...) decides.
T0 = datetime(2099, 11, 21, 22, 0, tzinfo=UTC)
CODE = "MOTOR_OVERHEAT"

FAULT_FIELDS = (
    "fault_code", "severity", "description", "first_occurred", "last_occurred", "last_passed",
    "occurrence_count", "status", "reporting_sources", "debounce_counter",
)

AUTO_CONFIRM_10S = {"confirmation_threshold": -3, "auto_confirm_after_sec": 10}


def at(seconds: float) -> datetime:
    return T0 + timedelta(seconds=seconds)


def fields_of(f: Fault) -> dict[str, object]:
    return {name: getattr(f, name) for name in FAULT_FIELDS}


def failed(
    ledger: FaultLedger,
    when: datetime,
    *,
    code: str = CODE,
    severity: int = 1,
    source: str = "/motor",
    description: str = "",
) -> None:
    result = ledger.report(
        code, "FAILED", severity=severity, description=description, source_id=source, at=when
    )
    assert result.accepted, result.message


def passed(
    ledger: FaultLedger, when: datetime, *, code: str = CODE, source: str = "/motor"
) -> None:
    result = ledger.report(code, "PASSED", severity=0, description="", source_id=source, at=when)
    assert result.accepted, result.message


def clear(ledger: FaultLedger, code: str = CODE) -> None:
    result = ledger.clear(code, actor="test:operator", reason="")
    assert result.success, result.message


def apply_step(ledger: FaultLedger, step: str, when: datetime) -> None:
    """F = FAILED, P = PASSED, C = operator clear."""
    if step == "F":
        failed(ledger, when)
    elif step == "P":
        passed(ledger, when)
    elif step == "C":
        clear(ledger)
    else:
        raise AssertionError(f"unknown step {step!r}")


def fault(ledger: FaultLedger, code: str = CODE) -> Fault:
    found = ledger.get_fault(code)
    assert found is not None, f"{code} should exist"
    return found


def status(ledger: FaultLedger, code: str = CODE) -> FaultStatus:
    return fault(ledger, code).status


def records(ledger: FaultLedger, kind: str) -> list[LogRecord]:
    return [r for r in ledger.history() if r.kind == kind]


# --------------------------------------------------------------------------------------------
# time-based confirmation
# --------------------------------------------------------------------------------------------


def test_timer_does_not_confirm_before_delay(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(**AUTO_CONFIRM_10S))
    failed(ledger, at(0))

    assert ledger.run_timers(now=at(9)) == 0
    assert status(ledger) == FaultStatus.PREFAILED


def test_timer_confirms_prefailed_fault_once_delay_has_passed(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(**AUTO_CONFIRM_10S))
    failed(ledger, at(0))

    assert ledger.run_timers(now=at(10)) == 1
    assert status(ledger) == FaultStatus.CONFIRMED


def test_timer_confirmation_is_announced_as_fault_confirmed(
    open_ledger: OpenLedger, notifications: Subscribe
) -> None:
    ledger = open_ledger(Policy(**AUTO_CONFIRM_10S))
    received = notifications(ledger)
    failed(ledger, at(0))

    ledger.run_timers(now=at(10))

    assert [(n.event_type, n.fault.fault_code, n.fault.status) for n in received] == [
        ("fault_confirmed", CODE, FaultStatus.CONFIRMED)
    ]


def test_timer_confirmation_is_logged_once(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(**AUTO_CONFIRM_10S))
    failed(ledger, at(0))

    ledger.run_timers(now=at(10))

    assert [r.fault_code for r in records(ledger, "fault_confirmed_by_timer")] == [CODE]


def test_later_timer_run_confirms_nothing_more(
    open_ledger: OpenLedger, notifications: Subscribe
) -> None:
    ledger = open_ledger(Policy(**AUTO_CONFIRM_10S))
    failed(ledger, at(0))
    ledger.run_timers(now=at(10))
    received = notifications(ledger)
    log_length = len(ledger.history())

    assert ledger.run_timers(now=at(20)) == 0
    assert (len(ledger.history()), received) == (log_length, [])


def test_timer_measures_from_the_last_failed(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(**AUTO_CONFIRM_10S))
    failed(ledger, at(0))
    failed(ledger, at(5))

    assert ledger.run_timers(now=at(10)) == 0
    assert status(ledger) == FaultStatus.PREFAILED
    assert ledger.run_timers(now=at(15)) == 1


def test_passed_does_not_restart_the_timer(open_ledger: OpenLedger) -> None:
    # FAILED then PASSED leaves the counter at 0 and the fault PREFAILED; the last FAILED is at 0.
    ledger = open_ledger(Policy(**AUTO_CONFIRM_10S))
    failed(ledger, at(0))
    passed(ledger, at(8))
    assert status(ledger) == FaultStatus.PREFAILED

    assert ledger.run_timers(now=at(10)) == 1


@pytest.mark.parametrize(
    ("policy", "steps", "expected_status"),
    [
        pytest.param(AUTO_CONFIRM_10S, ["F", "F", "F"], FaultStatus.CONFIRMED, id="confirmed"),
        pytest.param(AUTO_CONFIRM_10S, ["F", "P", "P"], FaultStatus.PREPASSED, id="prepassed"),
        pytest.param(
            {**AUTO_CONFIRM_10S, "confirmation_threshold": -1, "healing_enabled": True,
             "healing_threshold": 1},
            ["F", "P", "P"], FaultStatus.HEALED, id="healed",
        ),
        pytest.param(AUTO_CONFIRM_10S, ["F", "C"], FaultStatus.CLEARED, id="cleared"),
    ],
)
def test_timer_leaves_faults_that_are_not_prefailed_alone(
    open_ledger: OpenLedger,
    notifications: Subscribe,
    policy: dict[str, Any],
    steps: list[str],
    expected_status: FaultStatus,
) -> None:
    ledger = open_ledger(Policy(**policy))
    for i, step in enumerate(steps):
        apply_step(ledger, step, at(i))
    assert status(ledger) == expected_status
    received = notifications(ledger)

    assert ledger.run_timers(now=at(1000)) == 0
    assert (status(ledger), received, records(ledger, "fault_confirmed_by_timer")) == (
        expected_status, [], []
    )


def test_timer_is_off_when_auto_confirm_is_zero(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3, auto_confirm_after_sec=0.0))
    failed(ledger, at(0))

    assert ledger.run_timers(now=at(86_400)) == 0
    assert status(ledger) == FaultStatus.PREFAILED


def test_timer_returns_number_of_faults_it_confirmed(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(**AUTO_CONFIRM_10S))
    failed(ledger, at(0), code="FAN_STALL")
    failed(ledger, at(1), code="MOTOR_OVERHEAT")
    failed(ledger, at(5), code="LIDAR_TIMEOUT")

    assert ledger.run_timers(now=at(11)) == 2
    assert [status(ledger, c) for c in ("FAN_STALL", "MOTOR_OVERHEAT", "LIDAR_TIMEOUT")] == [
        FaultStatus.CONFIRMED, FaultStatus.CONFIRMED, FaultStatus.PREFAILED
    ]
    assert ledger.run_timers(now=at(15)) == 1


def test_timer_confirmation_survives_restart(open_ledger: OpenLedger) -> None:
    policy = Policy(**AUTO_CONFIRM_10S)
    first = open_ledger(policy)
    failed(first, at(0))
    first.run_timers(now=at(10))
    first.close()

    reopened = open_ledger(policy)

    assert status(reopened) == FaultStatus.CONFIRMED
    assert len(records(reopened, "fault_confirmed_by_timer")) == 1


# --------------------------------------------------------------------------------------------
# startup
# --------------------------------------------------------------------------------------------

HEALING = {"confirmation_threshold": -2, "healing_enabled": True, "healing_threshold": 2}
NO_HEALING = {**HEALING, "healing_enabled": False}

ALL_CODES = ["PREFAILED_ONE", "PREPASSED_ONE", "CONFIRMED_ONE", "HEALED_ONE", "CLEARED_ONE"]
NOT_HEALED_CODES = [code for code in ALL_CODES if code != "HEALED_ONE"]


def build_one_fault_per_status(ledger: FaultLedger) -> None:
    """With HEALING: one fault each PREFAILED, PREPASSED, CONFIRMED, HEALED, CLEARED."""
    failed(ledger, at(0), code="PREFAILED_ONE", description="flaky", source="/a")

    failed(ledger, at(1), code="PREPASSED_ONE", severity=2, source="/b")
    passed(ledger, at(2), code="PREPASSED_ONE")
    passed(ledger, at(3), code="PREPASSED_ONE")

    failed(ledger, at(4), code="CONFIRMED_ONE", source="/c")
    failed(ledger, at(5), code="CONFIRMED_ONE", severity=3, source="/a")
    passed(ledger, at(6), code="CONFIRMED_ONE")

    for i in range(2):
        failed(ledger, at(10 + i), code="HEALED_ONE")
    for i in range(4):
        passed(ledger, at(20 + i), code="HEALED_ONE")

    failed(ledger, at(30), code="CLEARED_ONE")
    clear(ledger, "CLEARED_ONE")
    failed(ledger, at(31), code="CLEARED_ONE")
    clear(ledger, "CLEARED_ONE")

    assert [status(ledger, code) for code in ALL_CODES] == [
        FaultStatus.PREFAILED, FaultStatus.PREPASSED, FaultStatus.CONFIRMED,
        FaultStatus.HEALED, FaultStatus.CLEARED,
    ]


def snapshot(ledger: FaultLedger, codes: list[str]) -> dict[str, dict[str, object]]:
    return {code: fields_of(fault(ledger, code)) for code in codes}


def heal_motor_then_close(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(**HEALING))
    failed(ledger, at(0))
    failed(ledger, at(1))
    for i in range(4):
        passed(ledger, at(2 + i))
    assert status(ledger) == FaultStatus.HEALED
    ledger.close()


def test_startup_without_healing_clears_healed_fault(open_ledger: OpenLedger) -> None:
    heal_motor_then_close(open_ledger)

    reopened = open_ledger(Policy(**NO_HEALING))

    assert status(reopened) == FaultStatus.CLEARED


def test_startup_reclassification_is_logged(open_ledger: OpenLedger) -> None:
    heal_motor_then_close(open_ledger)

    reopened = open_ledger(Policy(**NO_HEALING))

    assert [r.fault_code for r in records(reopened, "reclassified_on_startup")] == [CODE]


def test_startup_with_healing_leaves_healed_fault_alone(open_ledger: OpenLedger) -> None:
    heal_motor_then_close(open_ledger)

    reopened = open_ledger(Policy(**HEALING))

    assert status(reopened) == FaultStatus.HEALED
    assert records(reopened, "reclassified_on_startup") == []


def test_startup_without_healing_touches_only_healed_faults(open_ledger: OpenLedger) -> None:
    first = open_ledger(Policy(**HEALING))
    build_one_fault_per_status(first)
    before = snapshot(first, NOT_HEALED_CODES)
    first.close()

    reopened = open_ledger(Policy(**NO_HEALING))

    assert snapshot(reopened, NOT_HEALED_CODES) == before
    assert [r.fault_code for r in records(reopened, "reclassified_on_startup")] == ["HEALED_ONE"]


def test_startup_reclassification_happens_once(open_ledger: OpenLedger) -> None:
    heal_motor_then_close(open_ledger)
    second = open_ledger(Policy(**NO_HEALING))
    second.close()

    third = open_ledger(Policy(**NO_HEALING))

    assert len(records(third, "reclassified_on_startup")) == 1


def test_fault_cleared_on_startup_reactivates_on_failed(open_ledger: OpenLedger) -> None:
    heal_motor_then_close(open_ledger)
    reopened = open_ledger(Policy(**NO_HEALING))

    failed(reopened, at(100))

    reactivated = fault(reopened)
    assert (reactivated.status, reactivated.occurrence_count, reactivated.first_occurred) == (
        FaultStatus.PREFAILED, 2, at(100)
    )


def test_reopen_with_policy_none_keeps_state_exactly(open_ledger: OpenLedger) -> None:
    first = open_ledger(Policy(**HEALING))
    build_one_fault_per_status(first)
    before = snapshot(first, NOT_HEALED_CODES)
    first.close()

    reopened = open_ledger(None)

    assert snapshot(reopened, NOT_HEALED_CODES) == before


def test_reopen_with_policy_none_keeps_healed_fault(open_ledger: OpenLedger) -> None:
    # policy=None means "no new configuration": the recorded policy (healing on) stays effective.
    first = open_ledger(Policy(**HEALING))
    build_one_fault_per_status(first)
    before = snapshot(first, ["HEALED_ONE"])
    first.close()

    reopened = open_ledger(None)

    assert snapshot(reopened, ["HEALED_ONE"]) == before
    assert records(reopened, "reclassified_on_startup") == []


def test_reopen_with_same_policy_keeps_state_exactly(open_ledger: OpenLedger) -> None:
    first = open_ledger(Policy(**HEALING))
    build_one_fault_per_status(first)
    before = snapshot(first, ALL_CODES)
    first.close()

    reopened = open_ledger(Policy(**HEALING))

    assert snapshot(reopened, ALL_CODES) == before


def test_debounce_counter_survives_restart(open_ledger: OpenLedger) -> None:
    first = open_ledger(Policy(confirmation_threshold=-3))
    failed(first, at(0))
    failed(first, at(1))
    first.close()

    reopened = open_ledger(Policy(confirmation_threshold=-3))
    assert (status(reopened), fault(reopened).debounce_counter) == (
        FaultStatus.PREFAILED, -2
    )
    failed(reopened, at(2))

    assert status(reopened) == FaultStatus.CONFIRMED


def test_narrower_band_after_restart_clamps_stored_counter_before_next_step(
    open_ledger: OpenLedger,
) -> None:
    first = open_ledger(Policy(confirmation_threshold=-5))
    for i in range(5):
        failed(first, at(i))
    first.close()

    reopened = open_ledger(Policy(confirmation_threshold=-2))
    passed(reopened, at(10))

    # -5 clamped into [-2, 3] is -2, then +1
    assert (status(reopened), fault(reopened).debounce_counter) == (
        FaultStatus.CONFIRMED, -1
    )


@pytest.mark.parametrize(
    ("reopen_policy", "new_records"),
    [
        pytest.param(Policy(**HEALING), 0, id="same_policy_not_recorded_again"),
        pytest.param(None, 0, id="no_policy_not_recorded"),
        pytest.param(Policy(**NO_HEALING), 1, id="changed_policy_recorded"),
        pytest.param(Policy(**{**HEALING, "healing_threshold": 5}), 1,
                     id="changed_threshold_recorded"),
    ],
)
def test_policy_change_recorded_on_reopen(
    open_ledger: OpenLedger, reopen_policy: Policy | None, new_records: int
) -> None:
    first = open_ledger(Policy(**HEALING))
    failed(first, at(0))
    recorded = len(records(first, "policy_changed"))
    first.close()

    reopened = open_ledger(reopen_policy)

    assert len(records(reopened, "policy_changed")) == recorded + new_records
