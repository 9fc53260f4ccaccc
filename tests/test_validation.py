"""SPEC §4.5: rejected input gets a clear message, stores nothing and announces nothing."""

from __future__ import annotations

import re
from collections.abc import Callable
from datetime import UTC, datetime, timedelta, timezone
from typing import Any

import pytest

from faultledger import Fault, FaultLedger, FaultStatus, Notification, Policy, ReportResult

OpenLedger = Callable[..., FaultLedger]
Subscribe = Callable[[FaultLedger], list[Notification]]

T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)
CODE = "MOTOR_OVERHEAT"
UNKNOWN = "NO_SUCH_FAULT"

FAULT_FIELDS = (
    "fault_code", "severity", "description", "first_occurred", "last_occurred", "last_passed",
    "occurrence_count", "status", "reporting_sources", "debounce_counter",
)


def fields_of(f: Fault) -> dict[str, object]:
    return {name: getattr(f, name) for name in FAULT_FIELDS}


def fault(ledger: FaultLedger, code: str = CODE) -> Fault:
    found = ledger.get_fault(code)
    assert found is not None, f"{code} should exist"
    return found


def invalid_character(char: str) -> str:
    return (
        f"fault_code contains invalid character '{char}'. "
        "Only alphanumeric, underscore, hyphen, and dot are allowed"
    )


INVALID_CODES = [
    pytest.param("", "fault_code cannot be empty", id="empty"),
    pytest.param("A" * 129, "fault_code exceeds maximum length of 128", id="129_chars"),
    pytest.param("MOTOR OVERHEAT", invalid_character(" "), id="space"),
    pytest.param("MOTOR/OVERHEAT", invalid_character("/"), id="slash"),
    pytest.param("MOTOR:OVERHEAT", invalid_character(":"), id="colon"),
    pytest.param("MOTOR*", invalid_character("*"), id="asterisk"),
    pytest.param("MOTOR_ÜBERHITZT", invalid_character("Ü"), id="non_ascii_letter"),
    pytest.param("MOTOR_٣", invalid_character("٣"), id="non_ascii_digit"),
    pytest.param("MOTOR..OVERHEAT", "fault_code cannot contain '..'", id="double_dot_inside"),
    pytest.param("..MOTOR", "fault_code cannot contain '..'", id="double_dot_leading"),
    pytest.param("MOTOR...", "fault_code cannot contain '..'", id="triple_dot"),
]

# A valid FAILED report on CODE; each invalid case below changes one argument.
VALID_REPORT = {
    "fault_code": CODE,
    "event_type": "FAILED",
    "severity": 1,
    "description": "",
    "source_id": "/motor",
    "at": T0 + timedelta(seconds=30),
}

# (changed arguments, a word the clear message must contain, or None to only require a message)
INVALID_FIELDS = [
    pytest.param({"event_type": "BROKEN"}, "event_type", id="event_type_unknown_name"),
    pytest.param({"event_type": 2}, "event_type", id="event_type_2"),
    pytest.param({"event_type": -1}, "event_type", id="event_type_minus_1"),
    pytest.param({"severity": 4}, "severity", id="severity_4"),
    pytest.param({"severity": -1}, "severity", id="severity_minus_1"),
    pytest.param({"source_id": ""}, "source_id", id="source_id_empty"),
    pytest.param({"description": "x" * 4097}, "description", id="description_4097_chars"),
    pytest.param({"description": "bad\udcff"}, "description", id="description_lone_surrogate"),
    pytest.param({"at": datetime(2026, 11, 21, 22, 0, 30)}, None, id="at_naive_datetime"),
]

# Every invalid report, as changed arguments.
INVALID_REPORTS = [
    *(
        pytest.param({"fault_code": p.values[0]}, id=f"fault_code_{p.id}")
        for p in INVALID_CODES
    ),
    *(
        pytest.param({"fault_code": p.values[0], "event_type": "PASSED"},
                     id=f"passed_fault_code_{p.id}")
        for p in INVALID_CODES
    ),
    *(pytest.param(p.values[0], id=p.id) for p in INVALID_FIELDS),
]


def report(ledger: FaultLedger, **changes: Any) -> ReportResult:
    arguments: dict[str, Any] = {**VALID_REPORT, **changes}
    code = arguments.pop("fault_code")
    event_type = arguments.pop("event_type")
    return ledger.report(code, event_type, **arguments)


@pytest.fixture
def ledger(open_ledger: OpenLedger) -> FaultLedger:
    """A ledger holding one PREFAILED fault CODE, so an accepted report would change it."""
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    first = ledger.report(CODE, "FAILED", severity=1, description="hot", source_id="/motor", at=T0)
    assert first.accepted, first.message
    return ledger


# --------------------------------------------------------------------------------------------
# report(): rejections
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("event_type", ["FAILED", "PASSED"])
@pytest.mark.parametrize(("code", "message"), INVALID_CODES)
def test_invalid_fault_code_rejected_with_spec_message(
    ledger: FaultLedger, code: str, message: str, event_type: str
) -> None:
    result = report(ledger, fault_code=code, event_type=event_type)
    assert (result.accepted, result.message) == (False, message)


@pytest.mark.parametrize(("changes", "word"), INVALID_FIELDS)
def test_invalid_report_field_rejected_with_clear_message(
    ledger: FaultLedger, changes: dict[str, Any], word: str | None
) -> None:
    result = report(ledger, **changes)
    assert result.accepted is False
    assert result.message.strip() != ""
    if word is not None:
        assert word in result.message


@pytest.mark.parametrize("changes", INVALID_REPORTS)
def test_rejected_report_stores_nothing(ledger: FaultLedger, changes: dict[str, Any]) -> None:
    log_length = len(ledger.history())
    before = fields_of(fault(ledger))

    result = report(ledger, **changes)

    assert result.accepted is False
    assert result.seq is None
    assert len(ledger.history()) == log_length
    assert fields_of(fault(ledger)) == before


@pytest.mark.parametrize("changes", INVALID_REPORTS)
def test_rejected_report_creates_no_fault(ledger: FaultLedger, changes: dict[str, Any]) -> None:
    report(ledger, **changes)
    everything = ledger.list_faults(statuses=[s.value for s in FaultStatus])
    assert [f.fault_code for f in everything] == [CODE]


@pytest.mark.parametrize("changes", INVALID_REPORTS)
def test_rejected_report_emits_no_notification(
    ledger: FaultLedger, notifications: Subscribe, changes: dict[str, Any]
) -> None:
    received = notifications(ledger)
    # made CONFIRMED first, so an accepted FAILED or PASSED would announce fault_updated
    report(ledger, severity=3)
    received.clear()

    report(ledger, **changes)

    assert received == []


# --------------------------------------------------------------------------------------------
# report(): what is accepted
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "changes",
    [
        pytest.param({"fault_code": "A" * 128}, id="code_128_chars"),
        pytest.param({"fault_code": "x"}, id="code_1_char"),
        pytest.param({"fault_code": "Motor-1_overheat.v2"}, id="code_all_allowed_kinds"),
        pytest.param({"fault_code": "0123456789"}, id="code_digits"),
        pytest.param({"severity": 0}, id="severity_0"),
        pytest.param({"severity": 3}, id="severity_3"),
        pytest.param({"event_type": 0}, id="event_type_0"),
        pytest.param({"event_type": 1}, id="event_type_1"),
        pytest.param({"description": "x" * 4096}, id="description_4096_chars"),
        pytest.param({"description": "Überhitzung ✓ 過熱"}, id="description_unicode"),
        pytest.param({"source_id": "lidar"}, id="source_without_slash"),
        pytest.param({"at": None}, id="at_none_means_now"),
        pytest.param(
            {"at": datetime(2026, 11, 22, 0, 0, tzinfo=timezone(timedelta(hours=2)))},
            id="at_non_utc_aware",
        ),
    ],
)
def test_valid_report_accepted(ledger: FaultLedger, changes: dict[str, Any]) -> None:
    result = report(ledger, **changes)
    assert result.accepted is True, result.message


def test_accepted_report_is_stored_under_its_seq(ledger: FaultLedger) -> None:
    log_length = len(ledger.history())

    result = report(ledger)

    records = ledger.history()
    assert len(records) == log_length + 1
    [stored] = [r for r in records if r.seq == result.seq]
    assert (stored.kind, stored.fault_code) == ("fault_reported", CODE)


@pytest.mark.parametrize("severity", [4, -1, 99, 255])
def test_severity_is_checked_on_passed_as_on_failed(ledger: FaultLedger, severity: int) -> None:
    """medkit checks the severity on FAILED only; faultledger on PASSED too, with the same
    message (issue 18)."""
    log_length = len(ledger.history())

    passed = report(ledger, event_type="PASSED", severity=severity)
    failed = report(ledger, event_type="FAILED", severity=severity)

    assert passed.accepted is False and passed.reason == "invalid"
    assert passed.message == failed.message == (
        f"severity must be 0 (INFO) to 3 (CRITICAL), got {severity}")
    assert len(ledger.history()) == log_length


@pytest.mark.parametrize("severity", [0, 3])
def test_severity_on_passed_within_the_scale_is_accepted(ledger: FaultLedger,
                                                          severity: int) -> None:
    assert report(ledger, event_type="PASSED", severity=severity).accepted


# --------------------------------------------------------------------------------------------
# get and lookup
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("code", "message"), INVALID_CODES)
def test_get_fault_rejects_invalid_code_with_spec_message(
    ledger: FaultLedger, code: str, message: str
) -> None:
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        ledger.get_fault(code)


@pytest.mark.parametrize(("code", "message"), INVALID_CODES)
def test_lookup_fault_rejects_invalid_code_with_spec_message(
    ledger: FaultLedger, code: str, message: str
) -> None:
    result = ledger.lookup_fault(code)
    assert (result.success, result.message, result.fault) == (False, message, None)


def test_get_fault_unknown_returns_none(ledger: FaultLedger) -> None:
    assert ledger.get_fault(UNKNOWN) is None


def test_lookup_fault_unknown_says_not_found(ledger: FaultLedger) -> None:
    result = ledger.lookup_fault(UNKNOWN)
    assert (result.success, result.message, result.fault) == (
        False, f"Fault not found: {UNKNOWN}", None
    )


def test_lookup_fault_known_succeeds_with_empty_message(ledger: FaultLedger) -> None:
    result = ledger.lookup_fault(CODE)
    assert result.fault is not None
    assert (result.success, result.message, result.fault.fault_code) == (True, "", CODE)


# --------------------------------------------------------------------------------------------
# clear
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("code", "message"), INVALID_CODES)
def test_clear_rejects_invalid_code_with_spec_message(
    ledger: FaultLedger, code: str, message: str
) -> None:
    result = ledger.clear(code, actor="cli:alice", reason="")
    assert (result.success, result.message) == (False, message)


@pytest.mark.parametrize(
    "code", [*(p.values[0] for p in INVALID_CODES), UNKNOWN], ids=[
        *(p.id for p in INVALID_CODES), "unknown_code"
    ]
)
def test_failed_clear_stores_nothing(ledger: FaultLedger, code: str) -> None:
    log_length = len(ledger.history())
    before = fields_of(fault(ledger))

    ledger.clear(code, actor="cli:alice", reason="")

    assert len(ledger.history()) == log_length
    assert fields_of(fault(ledger)) == before


@pytest.mark.parametrize(
    "code", [*(p.values[0] for p in INVALID_CODES), UNKNOWN], ids=[
        *(p.id for p in INVALID_CODES), "unknown_code"
    ]
)
def test_failed_clear_emits_no_notification(
    ledger: FaultLedger, notifications: Subscribe, code: str
) -> None:
    received = notifications(ledger)
    ledger.clear(code, actor="cli:alice", reason="")
    assert received == []


def test_clear_unknown_fault_says_not_found(ledger: FaultLedger) -> None:
    result = ledger.clear(UNKNOWN, actor="cli:alice", reason="")
    assert (result.success, result.message) == (False, f"Fault not found: {UNKNOWN}")


def test_clear_known_fault_says_cleared(ledger: FaultLedger) -> None:
    result = ledger.clear(CODE, actor="cli:alice", reason="")
    assert (result.success, result.message) == (True, f"Fault cleared: {CODE}")
    assert fault(ledger).status == FaultStatus.CLEARED


def test_clear_of_already_cleared_fault_succeeds(ledger: FaultLedger) -> None:
    ledger.clear(CODE, actor="cli:alice", reason="")
    result = ledger.clear(CODE, actor="cli:bob", reason="again")
    assert (result.success, result.message) == (True, f"Fault cleared: {CODE}")


def test_clear_is_logged_with_actor_and_reason(ledger: FaultLedger) -> None:
    ledger.clear(CODE, actor="cli:alice", reason="replaced the fan")

    [record] = [r for r in ledger.history() if r.kind == "fault_cleared"]
    assert record.fault_code == CODE
    assert {"cli:alice", "replaced the fan"} <= set(record.payload.values())
