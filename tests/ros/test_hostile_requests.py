"""Hostile requests to a real `faultledger serve` (issue "Hardening"): every one is answered,
refusals are clear, the process never ends and its log stays small.

``TestHostileRequests`` sends hand-picked extremes to one manager, then checks it still
accepts and lists a valid report. ``TestFuzz`` sends 200 requests drawn by hypothesis (fixed
seed: ``derandomize``) across every service to another; valid reports mixed in must all be
accepted.
"""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import pytest
from builtin_interfaces.msg import Time
from faultledger_msgs.srv import GetHistory, GetStatistics, ReportFaultOnce, ReportGoalOutcome
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from ros2_medkit_msgs.srv import (
    ClearFault,
    GetFault,
    ListFaults,
    ListFaultsForEntity,
    ReportFault,
)

if TYPE_CHECKING:
    from tests.ros.conftest import Manager, ManagerFactory, RosClient

NS = "/fault_manager"
FAILED, PASSED = 0, 1
MAX_SEC = 2**31 - 1
MB = 1_000_000
ALL_STATUSES = ["PREFAILED", "PREPASSED", "CONFIRMED", "HEALED", "CLEARED"]
LOG_PER_REQUEST = 1024
"""Bytes of log one request may cost at most, whatever its size."""

SERVICES: dict[Any, str] = {
    ReportFault: f"{NS}/report_fault", ReportFaultOnce: f"{NS}/report_fault_once",
    ListFaults: f"{NS}/list_faults", GetFault: f"{NS}/get_fault",
    ClearFault: f"{NS}/clear_fault", ListFaultsForEntity: f"{NS}/list_faults_for_entity",
    GetHistory: f"{NS}/get_history", GetStatistics: f"{NS}/get_statistics",
    ReportGoalOutcome: f"{NS}/report_goal_outcome",
}


def srv_type(request: Any) -> Any:
    """The service type of a request message (``ReportFault.Request`` → ``ReportFault``)."""
    for kind in SERVICES:
        if isinstance(request, kind.Request):
            return kind
    raise AssertionError(f"not a fault manager request: {request!r}")


def call(client: RosClient, request: Any, timeout: float = 30.0) -> Any:
    kind = srv_type(request)
    return client.call(kind, SERVICES[kind], request, timeout=timeout)


def log_size(fault_manager: Manager) -> int:
    return fault_manager.stderr_path.stat().st_size


@dataclass
class Case:
    """One hostile request and what its answer must say."""

    id: str
    request: Callable[[], Any]
    check: Callable[[Any], None]


def refused(*words: str) -> Callable[[Any], None]:
    """The answer failed and its message (one line, bounded) contains ``words``."""
    def check(answer: Any) -> None:
        flag = answer.success if hasattr(answer, "success") else answer.accepted
        text = str(getattr(answer, "message", None) or getattr(answer, "error_message", ""))
        assert flag is False, f"expected a refusal, got {answer!r:.300}"
        assert "\n" not in text and len(text) < 600, text[:700]
        for word in words:
            assert word in text, f"{word!r} not in {text!r}"
    return check


def not_accepted(answer: Any) -> None:
    assert answer.accepted is False


def answered(answer: Any) -> None:
    """Any answer will do (the request is odd but legitimate)."""


def succeeded(answer: Any) -> None:
    assert answer.success is True, getattr(answer, "message", "") or answer.error_message


def saturated_rows(answer: Any) -> None:
    """Periods in 2100: their start/end are sent as the largest Time, not wrapped to 1901."""
    assert answer.success is True, answer.message
    assert len(answer.rows) == 24
    assert all((r.start.sec, r.start.nanosec) == (MAX_SEC, 999_999_999) for r in answer.rows)


STATS, HISTORY = GetStatistics.Request, GetHistory.Request
CASES = [
    # get_statistics
    Case("stats-until-9999", lambda: STATS(until="9999-12-31"),
         refused("outside the times the log can hold")),
    Case("stats-since-0001", lambda: STATS(since="0001-01-01"),
         refused("outside the times the log can hold")),
    Case("stats-as_of-negative", lambda: STATS(as_of=Time(sec=-1)),
         refused("as_of must not be before 1970")),
    Case("stats-as_of-nanosec", lambda: STATS(as_of=Time(sec=1, nanosec=2_000_000_000)),
         refused("as_of.nanosec must be below 1,000,000,000")),
    Case("stats-since_time-min", lambda: STATS(since_time=Time(sec=-(2**31))),
         refused("since_time must not be before 1970")),
    Case("stats-until_time-nanosec",
         lambda: STATS(until_time=Time(sec=MAX_SEC, nanosec=2**32 - 1)),
         refused("until_time.nanosec must be below")),
    Case("stats-until_time-2038", lambda: STATS(until_time=Time(sec=MAX_SEC)), succeeded),
    Case("stats-by-bogus", lambda: STATS(by="bogus"), refused("by must be one of")),
    Case("stats-by-escape-MB", lambda: STATS(by="\x1b[2J" * (MB // 4)),
         refused("by must be one of")),
    Case("stats-group_by-garbage", lambda: STATS(group_by=["code", "code", "\x1b[31m", "x" * MB]),
         refused("group_by")),
    Case("stats-codes-MB", lambda: STATS(codes=["X" * MB]), refused()),
    Case("stats-codes-10000", lambda: STATS(codes=["A"] * 10_000), refused()),
    Case("stats-shift-id-garbage", lambda: STATS(since="2026-11-20/\x07bogus"), refused()),
    Case("stats-in-2100", lambda: STATS(by="hour", since="2100-01-01T00:00Z",
                                        until="2100-01-02T00:00Z"), saturated_rows),
    # get_history
    Case("history-since-max", lambda: HISTORY(since=Time(sec=MAX_SEC, nanosec=999_999_999)),
         succeeded),
    Case("history-since-negative", lambda: HISTORY(since=Time(sec=-1)),
         refused("since must not be before 1970")),
    Case("history-until-nanosec", lambda: HISTORY(until=Time(sec=5, nanosec=2**32 - 1)),
         refused("until.nanosec must be below")),
    Case("history-limit-0", lambda: HISTORY(limit=0), succeeded),
    Case("history-limit-max", lambda: HISTORY(limit=2**32 - 1), succeeded),
    Case("history-kinds-bogus", lambda: HISTORY(kinds=["bogus", "\x00x", "k" * MB]), refused()),
    Case("history-code-MB", lambda: HISTORY(fault_code="x" * MB, source_id="s" * MB), answered),
    Case("history-reversed", lambda: HISTORY(since=Time(sec=2_000_000_000),
                                             until=Time(sec=1_000_000_000)), answered),
    # report_fault / report_fault_once
    Case("report-MB-fields", lambda: ReportFault.Request(
        fault_code="A" * MB, event_type=FAILED, severity=1, description="d" * MB,
        source_id="/s" * (MB // 2)), not_accepted),
    Case("report-severity-255", lambda: ReportFault.Request(
        fault_code="HOSTILE_SEV", event_type=FAILED, severity=255, source_id="/h"),
        not_accepted),
    Case("report-event_type-255", lambda: ReportFault.Request(
        fault_code="HOSTILE_EVT", event_type=255, severity=1, source_id="/h"), not_accepted),
    Case("report-empty", lambda: ReportFault.Request(), not_accepted),
    Case("report-controls", lambda: ReportFault.Request(
        fault_code="\x1b[2J\r\n", event_type=FAILED, severity=1, source_id="\x1b]8;;x\x07"),
        not_accepted),
    Case("report-once-event_id-MB", lambda: ReportFaultOnce.Request(
        event_id="e" * MB, fault_code="HOSTILE_ONCE", event_type=FAILED, severity=1,
        source_id="/h"), refused("event_id must be a UUID")),
    Case("report-once-empty", lambda: ReportFaultOnce.Request(), refused()),
    # report_goal_outcome
    Case("goal-MB-fields", lambda: ReportGoalOutcome.Request(
        action="/a" * (MB // 2), goal_id="g" * MB, status="ABORTED", server_node="n" * MB),
        refused("action exceeds maximum length")),
    Case("goal-empty", lambda: ReportGoalOutcome.Request(), refused("action cannot be empty")),
    Case("goal-controls", lambda: ReportGoalOutcome.Request(
        action="/x", goal_id="\x1b[2J\r\n", status="ABORTED"),
        refused("goal_id contains a control character")),
    Case("goal-status-MB", lambda: ReportGoalOutcome.Request(
        action="/x", goal_id="g", status="S" * MB), refused("status must be")),
    Case("goal-stamp-negative", lambda: ReportGoalOutcome.Request(
        action="/x", goal_id="g", status="ABORTED", stamp=Time(sec=-(2**31))),
        refused("stamp must not be before 1970")),
    Case("goal-stamp-nanosec", lambda: ReportGoalOutcome.Request(
        action="/x", goal_id="g", status="ABORTED", stamp=Time(sec=1, nanosec=2**32 - 1)),
        refused("stamp.nanosec must be below")),
    # clear_fault, get_fault, list_faults, list_faults_for_entity
    Case("clear-empty", lambda: ClearFault.Request(), refused("fault_code cannot be empty")),
    Case("clear-MB", lambda: ClearFault.Request(fault_code="c" * MB), refused("maximum length")),
    Case("clear-escape", lambda: ClearFault.Request(fault_code="\x1b[31m../x"),
         refused("invalid character")),
    Case("get-MB", lambda: GetFault.Request(fault_code="g" * MB), refused("maximum length")),
    Case("list-10000-statuses", lambda: ListFaults.Request(
        statuses=[f"STATUS_{i}" for i in range(10_000)], filter_by_severity=True,
        severity=255), answered),
    Case("list-MB-statuses", lambda: ListFaults.Request(statuses=["S" * 100] * 10_000),
         answered),
    Case("entity-empty", lambda: ListFaultsForEntity.Request(), refused()),
    Case("entity-MB", lambda: ListFaultsForEntity.Request(entity_id="e" * MB), answered),
]


@pytest.fixture(scope="class")
def fault_manager(shared_manager: ManagerFactory) -> Manager:
    """One fault manager for the tests of a class."""
    return shared_manager()


class TestHostileRequests:
    """One manager takes every case, then must still serve a valid report."""

    @pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
    def test_answered_and_logged_in_one_short_line(self, fault_manager: Manager,
                                                   shared_client: RosClient, case: Case) -> None:
        before = log_size(fault_manager)
        answer = call(shared_client, case.request())
        case.check(answer)
        assert fault_manager.running, fault_manager.describe()
        written = log_size(fault_manager) - before
        assert written < LOG_PER_REQUEST, (
            f"{case.id} wrote {written} bytes of log:\n{fault_manager.stderr_text()[before:]}")

    def test_nul_in_a_ros_string_arrives_truncated(self, fault_manager: Manager,
                                                   shared_client: RosClient) -> None:
        """What these wheels do (docs/ros.md): a ROS string ends at its first NUL, on the
        client's side, silently; the manager can only see and store the part before it. This
        is why FaultReporter refuses NUL locally (test_guard.py)."""
        request = ReportFault.Request(fault_code="NUL_CODE\x00HIDDEN", event_type=FAILED,
                                      severity=3, description="before\x00after",
                                      source_id="/nul\x00/hidden")
        assert call(shared_client, request).accepted is True
        fault = shared_client.fault("NUL_CODE")
        assert fault.description == "before"
        assert list(fault.reporting_sources) == ["/nul"]

    def test_startup_states_the_network_scope(self, fault_manager: Manager) -> None:
        network = [line for line in fault_manager.stdout_lines
                   if line.startswith("fault_manager network: ")]
        assert network == [
            "fault_manager network: discovery=LOCALHOST (ROS_AUTOMATIC_DISCOVERY_RANGE) "
            f"static_peers=none domain_id={os.environ.get('ROS_DOMAIN_ID', '0')} "
            "rmw=rmw_fastrtps_cpp security=off "
            "dds_profile=faultledger (announces every 0.5 s)"], fault_manager.stdout_lines

    def test_still_serving_afterwards(self, fault_manager: Manager,
                                      shared_client: RosClient) -> None:
        assert shared_client.report("AFTER_THE_STORM", FAILED, 3, "still here", "/pytest")
        codes = [f.fault_code for f in shared_client.list_faults(["CONFIRMED"])]
        assert "AFTER_THE_STORM" in codes
        assert fault_manager.running, fault_manager.describe()
        log = fault_manager.stderr_text()
        assert len(log.encode()) < len(CASES) * LOG_PER_REQUEST, log[-4000:]
        assert all(len(line.encode()) < LOG_PER_REQUEST for line in log.splitlines())
        assert "Traceback" not in log


def test_serve_stops_when_security_is_requested_but_missing(tmp_path: Path) -> None:
    """The wheels' Fast DDS has no security: serve must say so, not run unsecured."""
    keystore = tmp_path / "keystore" / "enclaves"
    keystore.mkdir(parents=True)
    for name in ("identity_ca.cert.pem", "cert.pem", "key.pem", "permissions_ca.cert.pem",
                 "governance.p7s", "permissions.p7s"):
        (keystore / name).write_text("not a certificate\n")
    env = {**os.environ, "ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": "Enforce",
           "ROS_SECURITY_KEYSTORE": str(keystore.parent)}
    done = subprocess.run(
        [sys.executable, "-m", "faultledger.cli.main", "serve", "--db",
         f"sqlite:///{tmp_path / 'faults.db'}"], env=env, cwd=tmp_path, capture_output=True,
        text=True, timeout=60, check=False)
    assert done.returncode == 2, (done.stdout, done.stderr[-2000:])
    assert "security=requested (Enforce, keystore" in done.stdout
    assert "fault_manager ready" not in done.stdout
    assert "doesn't have the security libraries" in done.stderr
    assert "docs/ros.md, 'Network scope and security'" in done.stderr


# -- fuzz ------------------------------------------------------------------------------------------
TEXT = st.one_of(
    st.text(st.characters(codec="utf-8"), max_size=40),
    st.sampled_from(["", "A", "MOTOR_OVERHEAT", "/robot/arm", "..", "\x00", "\x1b[2J",
                     "9999-12-31", "0001-01-01", "2026-11-21/night", "CONFIRMED"]),
    st.builds(lambda part, count: part * count, st.sampled_from(["A", "\x1b", "é", "\x00x"]),
              st.sampled_from([300, 5_000, 100_000])),
)
TIMES = st.sampled_from([
    (0, 0), (-1, 0), (-(2**31), 0), (1, 0), (5, 2**32 - 1), (5, 1_000_000_000),
    (MAX_SEC, 999_999_999), (1_795_300_000, 0), (1_795_300_000, 1), (1_795_386_400, 500_000),
])
BOUNDS = st.sampled_from(["", "2026-11-20", "2026-11-21", "2026-11-21/night", "2026-11-21T06:00",
                          "9999-12-31", "0001-01-01", "2038-01-19", "2262-04-11", "garbage",
                          "2026-11-21/bogus"])


def time_of(pair: tuple[int, int]) -> Any:
    return Time(sec=pair[0], nanosec=pair[1])


_valid_codes = itertools.count()


@st.composite
def valid_report(draw: st.DrawFn) -> Any:
    kind = draw(st.sampled_from([ReportFault, ReportFaultOnce]))
    request = kind.Request(fault_code=f"FUZZ_{next(_valid_codes)}", event_type=FAILED,
                           severity=draw(st.integers(0, 3)),
                           description=draw(st.text(st.characters(
                               codec="utf-8", exclude_characters="\x00"), max_size=200)),
                           source_id="/fuzz/valid")
    if kind is ReportFaultOnce:
        request.event_id = str(draw(st.uuids()))
    return request


def requests() -> st.SearchStrategy[Any]:
    uint8 = st.integers(0, 255)
    return st.one_of(
        valid_report(),
        st.builds(ReportFault.Request, fault_code=TEXT, event_type=uint8, severity=uint8,
                  description=TEXT, source_id=TEXT),
        st.builds(ReportFaultOnce.Request, event_id=TEXT, fault_code=TEXT, event_type=uint8,
                  severity=uint8, description=TEXT, source_id=TEXT),
        st.builds(ListFaults.Request, filter_by_severity=st.booleans(), severity=uint8,
                  statuses=st.lists(st.one_of(TEXT, st.sampled_from(ALL_STATUSES)),
                                    max_size=20)),
        st.builds(GetFault.Request, fault_code=TEXT),
        st.builds(ClearFault.Request, fault_code=TEXT),
        st.builds(ListFaultsForEntity.Request, entity_id=TEXT),
        st.builds(GetHistory.Request, fault_code=TEXT, source_id=TEXT,
                  since=TIMES.map(time_of), until=TIMES.map(time_of),
                  kinds=st.lists(st.one_of(TEXT, st.sampled_from(
                      ["fault_reported", "fault_cleared", "policy_changed"])), max_size=4),
                  limit=st.sampled_from([0, 1, 10_000, 2**32 - 1])),
        st.builds(GetStatistics.Request,
                  by=st.one_of(st.sampled_from(["", "shift", "day", "hour", "10min"]), TEXT),
                  since=BOUNDS, until=BOUNDS, since_time=TIMES.map(time_of),
                  until_time=TIMES.map(time_of), as_of=TIMES.map(time_of),
                  codes=st.lists(TEXT, max_size=4),
                  group_by=st.lists(st.one_of(st.sampled_from(["code", "source", "severity"]),
                                              TEXT), max_size=4)),
    )


class TestFuzz:
    """200 drawn requests to one manager: all answered, valid reports all accepted."""

    accepted: ClassVar[list[str]] = []

    @settings(max_examples=200, derandomize=True, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                     HealthCheck.large_base_example])
    @given(request=requests())
    def test_every_request_is_answered(self, fault_manager: Manager, shared_client: RosClient,
                                       request: Any) -> None:
        answer = call(shared_client, request)  # ServiceTimeout when unanswered
        assert fault_manager.running, fault_manager.describe()
        if getattr(request, "source_id", None) == "/fuzz/valid":
            assert answer.accepted is True, f"{request!r:.300} → {answer!r:.300}"
            self.accepted.append(request.fault_code)

    def test_alive_and_every_valid_report_stored(self, fault_manager: Manager,
                                                 shared_client: RosClient) -> None:
        assert fault_manager.running, fault_manager.describe()
        assert self.accepted, "the fuzz drew no valid report"
        stored = {f.fault_code for f in shared_client.list_faults(ALL_STATUSES)}
        missing = [code for code in self.accepted if code not in stored]
        assert not missing, missing
        log = fault_manager.stderr_text()
        assert all(len(line.encode()) < LOG_PER_REQUEST for line in log.splitlines())
        assert "internal error" not in log and "Traceback" not in log, log[-4000:]
