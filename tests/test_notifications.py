"""SPEC §4.4: which reports and clears announce which event, and what the event carries."""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from typing import Any

import pytest

from faultledger import Fault, FaultLedger, FaultStatus, Notification, Policy

OpenLedger = Callable[..., FaultLedger]
Subscribe = Callable[[FaultLedger], list[Notification]]

T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)
CODE = "MOTOR_OVERHEAT"

CONFIRMED = "fault_confirmed"
UPDATED = "fault_updated"
CLEARED = "fault_cleared"

FAULT_FIELDS = (
    "fault_code", "severity", "description", "first_occurred", "last_occurred", "last_passed",
    "occurrence_count", "status", "reporting_sources", "debounce_counter",
)


def at(seconds: float) -> datetime:
    return T0 + timedelta(seconds=seconds)


def fields_of(f: Fault) -> dict[str, object]:
    return {name: getattr(f, name) for name in FAULT_FIELDS}


def fault(ledger: FaultLedger, code: str = CODE) -> Fault:
    found = ledger.get_fault(code)
    assert found is not None, f"{code} should exist"
    return found


# Steps: F = FAILED (WARN), F! = FAILED (CRITICAL), P = PASSED, C = operator clear.
def apply_step(ledger: FaultLedger, step: str, when: datetime, *, code: str = CODE) -> None:
    if step == "C":
        cleared = ledger.clear(code, actor="test:operator", reason="")
        assert cleared.success, cleared.message
        return
    event_type, severity = {"F": ("FAILED", 1), "F!": ("FAILED", 3), "P": ("PASSED", 0)}[step]
    result = ledger.report(
        code, event_type, severity=severity, description="", source_id="/motor", at=when
    )
    assert result.accepted, result.message


def events_per_step(
    ledger: FaultLedger, received: list[Notification], steps: list[str]
) -> list[list[str]]:
    """The event types announced by each step, in order."""
    per_step: list[list[str]] = []
    for i, step in enumerate(steps):
        already = len(received)
        apply_step(ledger, step, at(i))
        per_step.append([n.event_type for n in received[already:]])
    return per_step


CONFIRM_AT_1 = {"confirmation_threshold": -1}
CONFIRM_AT_3 = {"confirmation_threshold": -3}
CONFIRM_AT_1_HEAL_AT_1 = {"confirmation_threshold": -1, "healing_enabled": True,
                          "healing_threshold": 1}
CONFIRM_AT_3_HEAL_AT_3 = {"confirmation_threshold": -3, "healing_enabled": True,
                          "healing_threshold": 3}

EVENT_TABLE = [
    pytest.param(CONFIRM_AT_1, ["F"], [[CONFIRMED]], id="new_fault_born_confirmed"),
    pytest.param(CONFIRM_AT_3, ["F!"], [[CONFIRMED]], id="new_critical_fault_born_confirmed"),
    pytest.param(CONFIRM_AT_3, ["F"], [[]], id="new_prefailed_fault_is_silent"),
    pytest.param(CONFIRM_AT_3, ["F", "F", "F"], [[], [], [CONFIRMED]],
                 id="debounce_into_confirmed"),
    pytest.param(CONFIRM_AT_3, ["F", "F!"], [[], [CONFIRMED]],
                 id="critical_moves_prefailed_into_confirmed"),
    pytest.param(CONFIRM_AT_1, ["F", "F"], [[CONFIRMED], [UPDATED]],
                 id="failed_on_confirmed_is_update"),
    pytest.param(CONFIRM_AT_1, ["F", "F!"], [[CONFIRMED], [UPDATED]],
                 id="critical_failed_on_confirmed_is_update"),
    pytest.param(CONFIRM_AT_3_HEAL_AT_3, ["F!", "P"], [[CONFIRMED], [UPDATED]],
                 id="passed_leaving_confirmed_is_update"),
    pytest.param(CONFIRM_AT_1, ["F", "P", "P", "P", "P", "P"],
                 [[CONFIRMED], [UPDATED], [UPDATED], [UPDATED], [UPDATED], [UPDATED]],
                 id="passed_on_confirmed_without_healing_is_update"),
    pytest.param(CONFIRM_AT_1_HEAL_AT_1, ["F", "P", "P"], [[CONFIRMED], [UPDATED], [CLEARED]],
                 id="move_into_healed_is_fault_cleared"),
    pytest.param(CONFIRM_AT_1_HEAL_AT_1, ["F", "P", "P", "P", "F"],
                 [[CONFIRMED], [UPDATED], [CLEARED], [], []],
                 id="reports_on_healed_fault_staying_healed_are_silent"),
    pytest.param(CONFIRM_AT_1_HEAL_AT_1, ["F", "P", "P", "F", "F"],
                 [[CONFIRMED], [UPDATED], [CLEARED], [], [CONFIRMED]],
                 id="healed_to_confirmed_by_debounce"),
    pytest.param(CONFIRM_AT_1_HEAL_AT_1, ["F", "P", "P", "F!"],
                 [[CONFIRMED], [UPDATED], [CLEARED], [CONFIRMED]],
                 id="healed_to_confirmed_by_critical"),
    pytest.param(CONFIRM_AT_3_HEAL_AT_3, ["F", "P", "P", "P", "F", "F", "F", "F"],
                 [[], [], [], [], [], [], [], []],
                 id="prefailed_and_prepassed_moves_are_silent"),
    pytest.param({}, ["P"], [[]], id="passed_for_unknown_fault_is_silent"),
    pytest.param(CONFIRM_AT_1, ["F", "C", "P"], [[CONFIRMED], [CLEARED], []],
                 id="passed_on_cleared_fault_is_silent"),
    pytest.param(CONFIRM_AT_3, ["F", "C"], [[], [CLEARED]], id="clear_of_prefailed_fault"),
    pytest.param(CONFIRM_AT_1, ["F", "C"], [[CONFIRMED], [CLEARED]],
                 id="clear_of_confirmed_fault"),
    pytest.param(CONFIRM_AT_1_HEAL_AT_1, ["F", "P", "P", "C"],
                 [[CONFIRMED], [UPDATED], [CLEARED], [CLEARED]], id="clear_of_healed_fault"),
    pytest.param(CONFIRM_AT_1, ["F", "C", "C"], [[CONFIRMED], [CLEARED], [CLEARED]],
                 id="clear_of_already_cleared_fault"),
    pytest.param(CONFIRM_AT_1, ["F", "C", "F"], [[CONFIRMED], [CLEARED], [CONFIRMED]],
                 id="reactivation_born_confirmed"),
    pytest.param(CONFIRM_AT_3, ["F", "C", "F!"], [[], [CLEARED], [CONFIRMED]],
                 id="critical_reactivation_born_confirmed"),
    pytest.param(CONFIRM_AT_3, ["F", "F", "F", "C", "F"],
                 [[], [], [CONFIRMED], [CLEARED], []],
                 id="reactivation_below_threshold_is_silent"),
]


@pytest.mark.parametrize(("policy", "steps", "expected"), EVENT_TABLE)
def test_event_types_announced(
    open_ledger: OpenLedger,
    notifications: Subscribe,
    policy: dict[str, Any],
    steps: list[str],
    expected: list[list[str]],
) -> None:
    ledger = open_ledger(Policy(**policy))
    received = notifications(ledger)
    assert events_per_step(ledger, received, steps) == expected


def test_confirmed_event_carries_fault_state_after_the_change(
    open_ledger: OpenLedger, notifications: Subscribe
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    received = notifications(ledger)
    ledger.report(CODE, "FAILED", severity=1, description="hot", source_id="/b", at=at(0))
    ledger.report(CODE, "FAILED", severity=2, description="", source_id="/a", at=at(4))
    ledger.report(CODE, "FAILED", severity=1, description="hotter", source_id="/b", at=at(9))

    [event] = received
    assert event.event_type == CONFIRMED
    assert fields_of(event.fault) == {
        "fault_code": CODE,
        "severity": 2,
        "description": "hotter",
        "first_occurred": at(0),
        "last_occurred": at(9),
        "last_passed": None,
        "occurrence_count": 1,
        "status": FaultStatus.CONFIRMED,
        "reporting_sources": ("/a", "/b"),
        "debounce_counter": -3,
    }


def test_updated_event_carries_fault_state_after_passed(
    open_ledger: OpenLedger, notifications: Subscribe
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    ledger.report(CODE, "FAILED", severity=2, description="", source_id="/motor", at=at(0))
    received = notifications(ledger)

    ledger.report(CODE, "PASSED", severity=0, description="", source_id="/motor", at=at(5))

    [event] = received
    assert (event.event_type, event.fault.status, event.fault.debounce_counter,
            event.fault.last_passed) == (UPDATED, FaultStatus.CONFIRMED, 0, at(5))


def test_move_into_healed_announces_fault_cleared_with_status_healed(
    open_ledger: OpenLedger, notifications: Subscribe
) -> None:
    ledger = open_ledger(
        Policy(confirmation_threshold=-1, healing_enabled=True, healing_threshold=1)
    )
    ledger.report(CODE, "FAILED", severity=2, description="", source_id="/motor", at=at(0))
    ledger.report(CODE, "PASSED", severity=0, description="", source_id="/motor", at=at(1))
    received = notifications(ledger)

    ledger.report(CODE, "PASSED", severity=0, description="", source_id="/motor", at=at(2))

    [event] = received
    assert (event.event_type, event.fault.status) == (CLEARED, FaultStatus.HEALED)


@pytest.mark.parametrize(
    "steps_before_clear",
    [
        pytest.param(["F"], id="from_confirmed"),
        pytest.param(["F", "C"], id="from_cleared"),
    ],
)
def test_clear_announces_fault_cleared_with_status_cleared(
    open_ledger: OpenLedger, notifications: Subscribe, steps_before_clear: list[str]
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    for i, step in enumerate(steps_before_clear):
        apply_step(ledger, step, at(i))
    received = notifications(ledger)

    ledger.clear(CODE, actor="cli:alice", reason="replaced fan")

    [event] = received
    assert (event.event_type, event.fault.fault_code, event.fault.status) == (
        CLEARED, CODE, FaultStatus.CLEARED
    )


def test_event_fault_equals_stored_fault_after_each_step(
    open_ledger: OpenLedger, notifications: Subscribe
) -> None:
    ledger = open_ledger(
        Policy(confirmation_threshold=-2, healing_enabled=True, healing_threshold=1)
    )
    received = notifications(ledger)
    steps = ["F", "F", "F", "P", "P", "P", "F!", "C", "F!"]
    for i, step in enumerate(steps):
        already = len(received)
        apply_step(ledger, step, at(i))
        for event in received[already:]:
            assert fields_of(event.fault) == fields_of(fault(ledger)), (i, step)
    assert [n.event_type for n in received] == [
        CONFIRMED, UPDATED, UPDATED, UPDATED, CLEARED, CONFIRMED, CLEARED, CONFIRMED
    ]


def test_event_names_the_fault_it_is_about(
    open_ledger: OpenLedger, notifications: Subscribe
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    received = notifications(ledger)
    apply_step(ledger, "F", at(0), code="FAN_STALL")
    apply_step(ledger, "F", at(1), code="MOTOR_OVERHEAT")
    assert [n.fault.fault_code for n in received] == ["FAN_STALL", "MOTOR_OVERHEAT"]


def test_event_timestamp_is_timezone_aware(
    open_ledger: OpenLedger, notifications: Subscribe
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    received = notifications(ledger)
    apply_step(ledger, "F", at(0))
    [event] = received
    assert isinstance(event.timestamp, datetime)
    assert event.timestamp.utcoffset() is not None


def test_every_subscriber_receives_the_event(
    open_ledger: OpenLedger, notifications: Subscribe
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    first = notifications(ledger)
    second = notifications(ledger)
    apply_step(ledger, "F", at(0))
    assert ([n.event_type for n in first], [n.event_type for n in second]) == (
        [CONFIRMED], [CONFIRMED]
    )


def test_cancelled_subscription_receives_nothing(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    received: list[Notification] = []
    subscription = ledger.subscribe(received.append)
    apply_step(ledger, "F", at(0))
    subscription.cancel()

    apply_step(ledger, "F", at(1))
    apply_step(ledger, "C", at(2))

    assert [n.event_type for n in received] == [CONFIRMED]


def test_reopened_ledger_announces_only_new_changes(
    open_ledger: OpenLedger, notifications: Subscribe
) -> None:
    policy = Policy(confirmation_threshold=-1)
    first = open_ledger(policy)
    apply_step(first, "F", at(0))
    apply_step(first, "F", at(1), code="FAN_STALL")
    first.close()

    reopened = open_ledger(policy)
    received = notifications(reopened)
    apply_step(reopened, "F", at(10))

    assert [(n.event_type, n.fault.fault_code) for n in received] == [(UPDATED, CODE)]


def test_a_subscriber_that_reports_synchronously_is_refused_not_deadlocked(
    open_ledger: OpenLedger,
) -> None:
    ledger = open_ledger(Policy())
    answers: list[tuple[bool, str]] = []

    def reentrant(_n: object) -> None:
        result = ledger.report("SECOND", "FAILED", 2, "", "/cb")
        answers.append((result.accepted, result.message))

    ledger.subscribe(reentrant)
    assert ledger.report("FIRST", "FAILED", 2, "", "/x").accepted
    assert answers and answers[0][0] is False and "subscriber callback" in answers[0][1]
    assert ledger.get_fault("SECOND") is None
