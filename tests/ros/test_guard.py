"""The pieces of the ROS adapter's hardening that need no DDS traffic: ``guard.py`` (callbacks
that never raise, bounded log text), saturating conversions, refused request times, the
network scope line and the FaultReporter's local refusal of NUL (issue "Hardening")."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from builtin_interfaces.msg import Time
from faultledger_msgs.srv import GetStatistics
from rclpy.serialization import deserialize_message, serialize_message
from ros2_medkit_msgs.msg import Fault as FaultMsg
from ros2_medkit_msgs.msg import FaultEvent
from ros2_medkit_msgs.srv import ListFaults, ReportFault

from faultledger.domain.clock import MAX_NS, NS_PER_SECOND
from faultledger.domain.fault import Fault
from faultledger.domain.notifications import Notification
from faultledger.domain.types import FaultStatus
from faultledger.errors import InvalidInputError
from faultledger.ros import convert
from faultledger.ros.guard import clip, error_text, guard_callback, guard_service
from faultledger.ros.network import scope
from faultledger.ros.reporter import FaultReporter
from faultledger.service.ledger import FaultLedger

if TYPE_CHECKING:
    from tests.ros.conftest import RosClient

MAX_SEC = 2**31 - 1


class Lines:
    """A logger that keeps what it is given."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def warning(self, message: str, **_: Any) -> bool:
        self.lines.append(("warning", message))
        return True

    def error(self, message: str, **_: Any) -> bool:
        self.lines.append(("error", message))
        return True


# -- clip ------------------------------------------------------------------------------------------
def test_clip_keeps_short_text_and_escapes_controls() -> None:
    assert clip("MOTOR_OVERHEAT") == "MOTOR_OVERHEAT"
    assert clip("a\x1b[2J\nb\x00") == "a\\x1b[2J\\nb\\x00"
    assert clip(["x", 1]) == "['x', 1]"


def test_clip_bounds_a_megabyte() -> None:
    text = clip("A" * 1_000_000)
    assert text == "A" * 200 + "…(+999800 chars)"
    escaped = clip("\x00" * 1_000_000)  # every character grows fourfold when escaped
    assert len(escaped) < 250 and escaped.startswith("\\x00" * 50) and "chars)" in escaped
    assert "\n" not in clip("\n" * 10_000)


def test_error_text_names_unexpected_errors() -> None:
    assert error_text(InvalidInputError("by must be one of ...")) == "by must be one of ..."
    assert error_text(OverflowError("date value out of range")) == (
        "internal error: OverflowError: date value out of range")
    assert len(error_text(ValueError("x" * 1_000_000))) < 500


# -- guards ----------------------------------------------------------------------------------------
def test_guard_service_answers_failed_and_logs_one_line() -> None:
    log = Lines()

    def boom(_request: Any, _response: Any) -> Any:
        raise OverflowError("date value out of range")

    answer = guard_service(boom, log, "get_statistics")(GetStatistics.Request(),
                                                        GetStatistics.Response())
    assert answer.success is False
    assert answer.message == "internal error: OverflowError: date value out of range"
    assert len(log.lines) == 1
    level, line = log.lines[0]
    assert level == "error" and line.startswith("get_statistics: internal error: OverflowError")
    assert "(at test_guard.py:" in line


def test_guard_service_refusal_is_a_warning_with_the_ledger_message() -> None:
    log = Lines()

    def refuse(_request: Any, _response: Any) -> Any:
        raise InvalidInputError("since must be before until")

    answer = guard_service(refuse, log, "get_history")(ReportFault.Request(),
                                                       ReportFault.Response())
    assert answer.accepted is False
    assert log.lines == [("warning", "get_history: refused: since must be before until")]


def test_guard_service_of_a_type_without_flags_answers_empty() -> None:
    def boom(_request: Any, response: Any) -> Any:
        response.muted_count = 3
        raise RuntimeError("x")

    answer = guard_service(boom, Lines(), "list_faults")(ListFaults.Request(),
                                                         ListFaults.Response())
    assert list(answer.faults) == [] and answer.muted_count == 0  # a fresh response


def test_guard_callback_logs_at_most_once_per_interval() -> None:
    log = Lines()
    calls: list[int] = []

    def boom(value: int) -> None:
        calls.append(value)
        raise KeyError(value)

    guarded = guard_callback(boom, log, "/diagnostics", every_sec=3600.0)
    for i in range(10):
        assert guarded(i) is None
    assert calls == list(range(10))
    assert len(log.lines) == 1 and "KeyError" in log.lines[0][1]

    again = guard_callback(boom, log, "/x", every_sec=0.0)
    again(1)
    again(2)
    assert len(log.lines) == 3


# -- conversions -----------------------------------------------------------------------------------
@pytest.mark.parametrize(("ns", "sec", "nanosec"), [
    (0, 0, 0),
    (MAX_SEC * NS_PER_SECOND + 999_999_999, MAX_SEC, 999_999_999),
    (MAX_SEC * NS_PER_SECOND + NS_PER_SECOND, MAX_SEC, 999_999_999),  # 2038-01-19T03:14:08Z
    (MAX_NS, MAX_SEC, 999_999_999),  # 2262
    (-5, 0, 0),
])
def test_to_time_saturates(ns: int, sec: int, nanosec: int) -> None:
    stamp = convert.to_time(ns)
    assert (stamp.sec, stamp.nanosec) == (sec, nanosec)
    checked = Time(sec=stamp.sec, nanosec=stamp.nanosec, check_fields=True)  # in range
    assert deserialize_message(serialize_message(checked), Time) == checked


def test_fault_after_2038_converts_and_serialises() -> None:
    fault = Fault(fault_code="LATE", severity=2, description="", first_occurred_ns=MAX_NS - 10,
                  last_occurred_ns=MAX_NS, last_passed_ns=0, occurrence_count=2**40,
                  status=FaultStatus.CONFIRMED, reporting_sources=("/late",),
                  debounce_counter=-3)
    message = deserialize_message(serialize_message(convert.fault_msg(fault)), FaultMsg)
    assert message.last_occurred.sec == MAX_SEC
    assert message.occurrence_count == 2**32 - 1


def test_an_event_written_over_the_last_one_is_the_event_built_anew(tmp_path: Path) -> None:
    """The events publisher writes every event into one message (``event_msg(..., into)``):
    nothing of the event before may stay in it, whatever either of them held."""
    notifications: list[Notification] = []
    ledger = FaultLedger.open(f"sqlite:///{tmp_path / 'faults.db'}")
    try:
        ledger.subscribe(notifications.append)
        for source in ("/a", "/b", "/c"):  # three sources on the first fault
            ledger.report("MANY_SOURCES", "FAILED", severity=3, source_id=source,
                          description="a long description")
        ledger.report("BRAKE_OVERHEAT", "FAILED", severity=1, source_id="/d")
        ledger.clear("MANY_SOURCES")
    finally:
        ledger.close()
    assert len({n.fault.fault_code for n in notifications}) == 2
    reused = FaultEvent()
    for notification in notifications + notifications[::-1]:
        fresh = convert.event_msg(notification)
        assert convert.event_msg(notification, reused) is reused
        assert reused == fresh
        assert deserialize_message(serialize_message(reused), FaultEvent) == fresh
        assert list(fresh.fault.reporting_sources) == list(notification.fault.reporting_sources)


@pytest.mark.parametrize(("stamp", "words"), [
    (Time(sec=-1), "as_of must not be before 1970 (sec >= 0), got sec=-1"),
    (Time(sec=5, nanosec=2_000_000_000), "as_of.nanosec must be below 1,000,000,000"),
    (Time(sec=5, nanosec=1_000_000_000), "as_of.nanosec must be below 1,000,000,000"),
])
def test_bad_request_times_are_refused(stamp: Any, words: str) -> None:
    with pytest.raises(InvalidInputError) as refused:
        convert.stats_moment(stamp, "as_of")
    assert words in str(refused.value)


def test_good_request_times_pass() -> None:
    assert convert.request_ns(Time(sec=0, nanosec=0), "since") == 0
    assert convert.request_ns(Time(sec=MAX_SEC, nanosec=999_999_999), "since") == (
        MAX_SEC * NS_PER_SECOND + 999_999_999)


# -- network scope ---------------------------------------------------------------------------------
@pytest.mark.parametrize(("env", "expected"), [
    ({}, "discovery=SUBNET (default: ROS_AUTOMATIC_DISCOVERY_RANGE unset) static_peers=none "
         "domain_id=0 rmw=rmw_fastrtps_cpp security=off"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
     "discovery=LOCALHOST (ROS_AUTOMATIC_DISCOVERY_RANGE) static_peers=none domain_id=0 "
     "rmw=rmw_fastrtps_cpp security=off"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "10.0.0.2;robot.local"},
     "discovery=SUBNET (ROS_AUTOMATIC_DISCOVERY_RANGE) static_peers=10.0.0.2,robot.local "
     "domain_id=0 rmw=rmw_fastrtps_cpp security=off"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF", "ROS_STATIC_PEERS": "10.0.0.2"},
     "discovery=OFF (ROS_AUTOMATIC_DISCOVERY_RANGE) static_peers=none domain_id=0 "
     "rmw=rmw_fastrtps_cpp security=off"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "lan"},
     "discovery=LOCALHOST (ROS_AUTOMATIC_DISCOVERY_RANGE=lan is invalid; rcl assumes this) "
     "static_peers=none domain_id=0 rmw=rmw_fastrtps_cpp security=off"),
    ({"ROS_LOCALHOST_ONLY": "1", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"},
     "discovery=LOCALHOST (ROS_LOCALHOST_ONLY=1, deprecated) static_peers=none domain_id=0 "
     "rmw=rmw_fastrtps_cpp security=off"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_SECURITY_ENABLE": "true",
      "ROS_SECURITY_STRATEGY": "Enforce", "ROS_SECURITY_KEYSTORE": "/etc/keys"},
     "discovery=LOCALHOST (ROS_AUTOMATIC_DISCOVERY_RANGE) static_peers=none domain_id=0 "
     "rmw=rmw_fastrtps_cpp security=requested (Enforce, keystore /etc/keys)"),
])
def test_scope_line(env: dict[str, str], expected: str) -> None:
    assert scope(env).describe(0, "rmw_fastrtps_cpp") == expected


# -- FaultReporter: NUL never leaves the process ---------------------------------------------------
def test_reporter_refuses_nul_locally(client: RosClient) -> None:
    reporter = FaultReporter(client.node, "/test/nul", local_filtering=False)
    try:
        assert reporter.report("AB\x00CD", 2, "x") is False
        assert reporter.report("AB", 2, "bad\x00description") is False
        assert reporter.report("AB", 2, "x", source_id="/a\x00b") is False
        assert reporter.report_passed("AB\x00CD") is False
        assert reporter.report("AB", 999) is False
        assert reporter.pending == 0
        assert reporter.report("AB", 2, "fine") is True  # queued: no manager runs here
        assert reporter.pending == 1
    finally:
        reporter.destroy()
