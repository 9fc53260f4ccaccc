"""Service round trips against a real fault manager process (SPEC §4.5, §4.6, §8).

The tests of ``TestOneSharedManager`` share one manager (default policy: the first FAILED
confirms, no healing) and one client, each test on its own fault codes and sources; the tests
after it need another policy or a controlled log and start their own manager. Only one manager
runs at a time (they all serve /fault_manager/...).
"""

from __future__ import annotations

import json
import re
import signal
import time
import uuid
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from faultledger_msgs.srv import ReportFaultOnce
from ros2_medkit_msgs.msg import Fault as FaultMsg
from ros2_medkit_msgs.srv import (
    ClearFault,
    GetFault,
    ListFaults,
    ListFaultsForEntity,
    ReportFault,
)

from faultledger import FaultLedger
from faultledger.domain.validation import MAX_DESCRIPTION_LENGTH

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

FAILED, PASSED = 0, 1
NS = "/fault_manager"
ALL_STATUSES = ("PREFAILED", "PREPASSED", "CONFIRMED", "HEALED", "CLEARED")
INVALID_CHAR = ("fault_code contains invalid character '{}'. Only alphanumeric, underscore, "
                "hyphen, and dot are allowed")

# (fault_code, the §4.5 message get_fault / clear_fault must answer with)
INVALID_CODES = [
    pytest.param("", "fault_code cannot be empty", id="empty"),
    pytest.param("A" * 129, "fault_code exceeds maximum length of 128", id="too-long"),
    pytest.param("MOTOR OVERHEAT", INVALID_CHAR.format(" "), id="space"),
    pytest.param("motor/overheat", INVALID_CHAR.format("/"), id="slash"),
    pytest.param("MOTOR:1", INVALID_CHAR.format(":"), id="colon"),
    pytest.param("TEMP_\u00b0C", INVALID_CHAR.format("\u00b0"), id="non-ascii"),
    pytest.param("A..B", "fault_code cannot contain '..'", id="double-dot"),
    pytest.param("..", "fault_code cannot contain '..'", id="only-dots"),
]


@pytest.fixture(scope="class")
def served(shared_manager: ManagerFactory, shared_client: RosClient) -> RosClient:
    """The class's manager (default policy) and its client."""
    shared_manager()
    return shared_client


def now_ns() -> int:
    return time.time_ns()


def stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def codes(faults: list[Any], prefix: str) -> list[str]:
    return [f.fault_code for f in faults if f.fault_code.startswith(prefix)]


class TestOneSharedManager:
    """Default policy; one manager and one client for the whole class, codes per test."""

    # -- graph -------------------------------------------------------------------------------------
    def test_node_services_and_events_topic_are_advertised(self, served: RosClient) -> None:
        node = served.node
        expected_services = {
            f"{NS}/report_fault": "ros2_medkit_msgs/srv/ReportFault",
            f"{NS}/list_faults": "ros2_medkit_msgs/srv/ListFaults",
            f"{NS}/get_fault": "ros2_medkit_msgs/srv/GetFault",
            f"{NS}/clear_fault": "ros2_medkit_msgs/srv/ClearFault",
            f"{NS}/list_faults_for_entity": "ros2_medkit_msgs/srv/ListFaultsForEntity",
            f"{NS}/get_history": "faultledger_msgs/srv/GetHistory",
            f"{NS}/report_fault_once": "faultledger_msgs/srv/ReportFaultOnce",
            f"{NS}/report_goal_outcome": "faultledger_msgs/srv/ReportGoalOutcome",
            f"{NS}/acknowledge_fault": "faultledger_msgs/srv/AcknowledgeFault",
        }

        def graph_complete() -> bool:
            services = dict(node.get_service_names_and_types())
            topics = dict(node.get_topic_names_and_types())
            return (all(services.get(name) == [kind] for name, kind in expected_services.items())
                    and topics.get(f"{NS}/events") == ["ros2_medkit_msgs/msg/FaultEvent"])

        assert served.spin_until(graph_complete, 20.0), (
            f"services: {node.get_service_names_and_types()}\n"
            f"topics: {node.get_topic_names_and_types()}")
        assert served.spin_until(
            lambda: ("fault_manager", "/") in node.get_node_names_and_namespaces(), 10.0)
        # Every service under the node, also those its report loop serves (report_loop.py).
        assert served.spin_until(lambda: set(expected_services) <= set(dict(
            node.get_service_names_and_types_by_node("fault_manager", "/"))), 10.0)
        publishers = node.get_publishers_info_by_topic(f"{NS}/events")
        assert [p.node_name for p in publishers] == ["fault_manager"]
        qos = publishers[0].qos_profile
        assert qos.reliability.name == "RELIABLE"
        assert qos.durability.name == "VOLATILE"

    # -- report / get ------------------------------------------------------------------------------
    def test_report_and_get_round_trip_with_full_fault_data(self, served: RosClient) -> None:
        before = now_ns()
        assert served.report("SVC_RT_MOTOR", FAILED, 2, "winding hot", "/svc_rt/motor_left")
        response = served.get("SVC_RT_MOTOR")
        assert response.success, response.error_message
        assert response.error_message == ""
        fault = response.fault
        assert fault.fault_code == "SVC_RT_MOTOR"
        assert fault.severity == FaultMsg.SEVERITY_ERROR == 2
        assert fault.description == "winding hot"
        assert fault.status == FaultMsg.STATUS_CONFIRMED == "CONFIRMED"
        assert fault.occurrence_count == 1
        assert list(fault.reporting_sources) == ["/svc_rt/motor_left"]
        first = stamp_ns(fault.first_occurred)
        assert before - 5_000_000_000 <= first <= now_ns() + 5_000_000_000
        assert fault.last_occurred == fault.first_occurred
        assert stamp_ns(fault.last_passed) == 0, "last_passed must be zero when never passed"

        # PASSED from another source: last_passed set; sources, severity, description unchanged;
        # still CONFIRMED (no healing in the default policy).
        assert served.report("SVC_RT_MOTOR", PASSED, 0, "", "/svc_rt/motor_right")
        fault = served.fault("SVC_RT_MOTOR")
        assert stamp_ns(fault.last_passed) >= first
        assert fault.status == "CONFIRMED"
        assert list(fault.reporting_sources) == ["/svc_rt/motor_left"]
        assert (fault.severity, fault.description) == (2, "winding hot")

        # A lower-severity FAILED with an empty description: severity never lowered, description
        # kept; a second source joins the sorted set; last_occurred moves, first_occurred does not.
        assert served.report("SVC_RT_MOTOR", FAILED, 1, "", "/svc_rt/a_driver")
        fault = served.fault("SVC_RT_MOTOR")
        assert (fault.severity, fault.description) == (2, "winding hot")
        assert list(fault.reporting_sources) == ["/svc_rt/a_driver", "/svc_rt/motor_left"]
        assert stamp_ns(fault.first_occurred) == first
        assert stamp_ns(fault.last_occurred) > first
        assert fault.occurrence_count == 1

        # A higher severity and a new description replace the stored ones.
        assert served.report("SVC_RT_MOTOR", FAILED, 3, "winding burnt", "/svc_rt/motor_left")
        fault = served.fault("SVC_RT_MOTOR")
        assert (fault.severity, fault.description) == (3, "winding burnt")

    def test_passed_for_an_unknown_fault_is_accepted_and_stores_nothing(
            self, served: RosClient) -> None:
        assert served.report("SVC_PASS_ONLY", PASSED, 0, "", "/svc_pass")
        response = served.get("SVC_PASS_ONLY")
        assert not response.success
        assert response.error_message == "Fault not found: SVC_PASS_ONLY"

    @pytest.mark.parametrize(("fault_code", "event_type", "severity", "source_id", "description"), [
        pytest.param("", FAILED, 1, "/svc_bad", "", id="empty-code"),
        pytest.param("A" * 129, FAILED, 1, "/svc_bad", "", id="code-too-long"),
        pytest.param("SVC BAD", FAILED, 1, "/svc_bad", "", id="code-space"),
        pytest.param("SVC/BAD", FAILED, 1, "/svc_bad", "", id="code-slash"),
        pytest.param("SVC_\u00e9", FAILED, 1, "/svc_bad", "", id="code-non-ascii"),
        pytest.param("SVC..BAD", FAILED, 1, "/svc_bad", "", id="code-double-dot"),
        pytest.param("SVC_BAD_TYPE", 2, 1, "/svc_bad", "", id="event-type-2"),
        pytest.param("SVC_BAD_TYPE_255", 255, 1, "/svc_bad", "", id="event-type-255"),
        pytest.param("SVC_BAD_SEVERITY", FAILED, 4, "/svc_bad", "", id="severity-4"),
        pytest.param("SVC_BAD_SEVERITY_255", FAILED, 255, "/svc_bad", "", id="severity-255"),
        pytest.param("SVC_BAD_PASSED_SEVERITY", PASSED, 4, "/svc_bad", "", id="passed-severity-4"),
        pytest.param("SVC_BAD_PASSED_255", PASSED, 255, "/svc_bad", "", id="passed-severity-255"),
        pytest.param("SVC_BAD_SOURCE", FAILED, 1, "", "", id="empty-source"),
        pytest.param("SVC_BAD_DESCRIPTION", FAILED, 1, "/svc_bad",
                     "x" * (MAX_DESCRIPTION_LENGTH + 1), id="description-too-long"),
    ])
    def test_invalid_reports_are_rejected_and_store_nothing(
            self, served: RosClient, fault_code: str, event_type: int, severity: int,
            source_id: str, description: str) -> None:
        request = ReportFault.Request(fault_code=fault_code, event_type=event_type,
                                      severity=severity, description=description,
                                      source_id=source_id)
        assert served.call(ReportFault, f"{NS}/report_fault", request).accepted is False
        if fault_code.startswith("SVC_BAD_"):  # a valid code: nothing may have been created
            response = served.get(fault_code)
            assert (response.success, response.error_message) == (
                False, f"Fault not found: {fault_code}")
            assert list(served.history(fault_code=fault_code).records) == []

    def test_boundary_reports_are_accepted(self, served: RosClient) -> None:
        longest = "B" * 128
        assert served.report(longest, FAILED, 0, "", "/svc_edge")
        assert served.fault(longest).fault_code == longest
        for code in ("svc.edge-case_1.x", "SVC_EDGE.9", "svc-edge"):
            assert served.report(code, FAILED, 3, "", "/svc_edge"), code
            assert served.fault(code).severity == 3
        assert served.report("SVC_EDGE_DESC", FAILED, 1, "d" * MAX_DESCRIPTION_LENGTH, "/svc_edge")
        assert len(served.fault("SVC_EDGE_DESC").description) == MAX_DESCRIPTION_LENGTH
        # Severity 0..3 on PASSED too (medkit does not check it there; faultledger does).
        assert served.report("SVC_EDGE.9", PASSED, 3, "", "/svc_edge")
        assert stamp_ns(served.fault("SVC_EDGE.9").last_passed) > 0

    @pytest.mark.parametrize(("fault_code", "message"), INVALID_CODES)
    def test_get_fault_answers_validation_messages(self, served: RosClient, fault_code: str,
                                                   message: str) -> None:
        response = served.call(GetFault, f"{NS}/get_fault", GetFault.Request(fault_code=fault_code))
        assert (response.success, response.error_message) == (False, message)

    @pytest.mark.parametrize(("fault_code", "message"), INVALID_CODES)
    def test_clear_fault_answers_validation_messages(self, served: RosClient, fault_code: str,
                                                     message: str) -> None:
        response = served.call(ClearFault, f"{NS}/clear_fault",
                               ClearFault.Request(fault_code=fault_code))
        assert (response.success, response.message) == (False, message)

    def test_unknown_fault_on_get_and_clear(self, served: RosClient) -> None:
        response = served.get("SVC_NEVER_REPORTED")
        assert (response.success, response.error_message) == (
            False, "Fault not found: SVC_NEVER_REPORTED")
        cleared = served.clear("SVC_NEVER_REPORTED")
        assert (cleared.success, cleared.message) == (False, "Fault not found: SVC_NEVER_REPORTED")
        assert list(cleared.auto_cleared_codes) == []

    # -- clear -------------------------------------------------------------------------------------
    def test_clear_round_trip(self, served: RosClient) -> None:
        assert served.report("SVC_CLR", FAILED, 2, "bumper hit", "/svc_clr/bumper")
        before = served.fault("SVC_CLR")
        response = served.clear("SVC_CLR")
        assert (response.success, response.message) == (True, "Fault cleared: SVC_CLR")
        assert list(response.auto_cleared_codes) == []
        after = served.fault("SVC_CLR")
        assert after.status == "CLEARED"
        # Clearing changes the status only.
        for field in ("severity", "description", "first_occurred", "last_occurred", "last_passed",
                      "occurrence_count", "reporting_sources"):
            assert getattr(after, field) == getattr(before, field), field
        assert "SVC_CLR" not in codes(served.list_faults(), "SVC_CLR")
        assert codes(served.list_faults(["CLEARED"]), "SVC_CLR") == ["SVC_CLR"]

        # Clearing an already CLEARED fault succeeds again (medkit).
        again = served.clear("SVC_CLR")
        assert (again.success, again.message) == (True, "Fault cleared: SVC_CLR")

        # PASSED on a CLEARED fault is ignored; FAILED reactivates it.
        assert served.report("SVC_CLR", PASSED, 0, "", "/svc_clr/bumper")
        assert served.fault("SVC_CLR") == after
        assert served.report("SVC_CLR", FAILED, 0, "", "/svc_clr/bumper")
        reactivated = served.fault("SVC_CLR")
        assert reactivated.status == "CONFIRMED"
        assert reactivated.occurrence_count == 2
        assert reactivated.severity == 2, "severity is never lowered, also across reactivation"
        assert stamp_ns(reactivated.first_occurred) > stamp_ns(before.first_occurred)
        assert reactivated.first_occurred == reactivated.last_occurred

    # -- list_faults_for_entity --------------------------------------------------------------------
    def test_list_faults_for_entity(self, served: RosClient) -> None:
        reports = [
            ("E_DRIVE_HOT", "/robot/arm/entdrive"),
            ("E_DRIVE_BARE", "entdrive"),
            ("E_OTHER_PREFIX", "/robot/xentdrive"),
            ("E_SUBNODE", "/robot/entdrive/sub"),
            ("E_LATE_SOURCE", "/robot/other"),
        ]
        for code, source in reports:
            assert served.report(code, FAILED, 1, "", source)
        assert served.report("E_LATE_SOURCE", FAILED, 1, "", "/base/entdrive")
        assert served.clear("E_DRIVE_BARE").success  # any status is listed
        assert served.report("E_PASSED_ONLY", FAILED, 1, "", "/robot/unrelated")
        # A PASSED report does not make its source a reporting source.
        assert served.report("E_PASSED_ONLY", PASSED, 0, "", "/robot/entdrive")

        response = served.for_entity("entdrive")
        assert (response.success, response.error_message) == (True, "")
        assert sorted(f.fault_code for f in response.faults) == [
            "E_DRIVE_BARE", "E_DRIVE_HOT", "E_LATE_SOURCE"]
        by_code = {f.fault_code: f for f in response.faults}
        assert by_code["E_DRIVE_BARE"].status == "CLEARED"
        assert by_code["E_DRIVE_HOT"] == served.fault("E_DRIVE_HOT")

        assert [f.fault_code for f in served.for_entity("arm/entdrive").faults] == ["E_DRIVE_HOT"]
        nobody = served.for_entity("entity_nobody_reports")
        assert (nobody.success, list(nobody.faults)) == (True, [])

    def test_list_faults_for_entity_rejects_an_empty_id(self, served: RosClient) -> None:
        response = served.call(ListFaultsForEntity, f"{NS}/list_faults_for_entity",
                               ListFaultsForEntity.Request(entity_id=""))
        assert response.success is False
        assert response.error_message.strip() != ""
        assert list(response.faults) == []

    # -- get_history -------------------------------------------------------------------------------
    def test_report_fault_once_stores_a_retried_event_id_once(self, served: RosClient) -> None:
        def once(event_id: str, description: str) -> Any:
            request = ReportFaultOnce.Request(
                event_id=event_id, fault_code="ONCE_ESTOP", event_type=FAILED, severity=2,
                description=description, source_id="/once/estop")
            return served.call(ReportFaultOnce, f"{NS}/report_fault_once", request)

        key, other = str(uuid.uuid4()), str(uuid.uuid4())
        answers = [once(key, "press"), once(key, "press (retry)"), once(other, "2nd")]
        assert [(a.accepted, a.duplicate, a.message) for a in answers] == [
            (True, False, ""), (True, True, ""), (True, False, "")]
        records = served.history(fault_code="ONCE_ESTOP").records
        assert [(r.event_id, json.loads(r.payload_json)["description"]) for r in records] == [
            (key, "press"), (other, "2nd")]
        fault = served.get("ONCE_ESTOP").fault
        assert fault.description == "2nd"  # the retry's description was not applied either
        assert stamp_ns(fault.last_occurred) == stamp_ns(records[1].occurred_at)

        bad = once("not-a-uuid", "x")
        assert (bad.accepted, bad.duplicate) == (False, False)
        assert bad.message == "event_id must be a UUID, got 'not-a-uuid'"
        assert len(served.history(fault_code="ONCE_ESTOP").records) == 2

    def test_get_history_filters_and_record_data(self, served: RosClient) -> None:
        assert served.report("H_ALPHA", FAILED, 2, "first", "/hist/one")
        time.sleep(0.01)
        assert served.report("H_ALPHA", PASSED, 0, "", "/hist/two")
        time.sleep(0.01)
        assert served.report("H_BETA", FAILED, 1, "", "/hist/one")
        time.sleep(0.01)
        assert served.clear("H_ALPHA").success

        response = served.history(fault_code="H_ALPHA")
        assert (response.success, response.error_message) == (True, "")
        alpha = list(response.records)
        assert [r.kind for r in alpha] == ["fault_reported", "fault_reported", "fault_cleared"]
        assert [r.fault_code for r in alpha] == ["H_ALPHA"] * 3
        assert [r.source_id for r in alpha[:2]] == ["/hist/one", "/hist/two"]
        seqs = [r.seq for r in alpha]
        assert seqs == sorted(seqs) and len(set(seqs)) == 3
        for record in alpha:
            assert record.schema_version == 1
            assert re.fullmatch(r"[0-9a-f]{64}", record.hash), record.hash
            assert re.fullmatch(r"[0-9a-f-]{36}", record.event_id), record.event_id
            assert stamp_ns(record.occurred_at) > 0 and stamp_ns(record.recorded_at) > 0
            assert json.loads(record.payload_json)["fault_code"] == "H_ALPHA"
        first_payload = json.loads(alpha[0].payload_json)
        assert first_payload["event_type"] == "FAILED"
        assert (first_payload["severity"], first_payload["description"]) == (2, "first")
        assert first_payload["source_id"] == "/hist/one"

        by_source = list(served.history(source_id="/hist/one").records)
        assert [(r.fault_code, r.kind) for r in by_source] == [
            ("H_ALPHA", "fault_reported"), ("H_BETA", "fault_reported")]

        cleared = list(served.history(fault_code="H_ALPHA", kinds=["fault_cleared"]).records)
        assert [r.seq for r in cleared] == [alpha[2].seq]
        reported = list(served.history(fault_code="H_ALPHA", kinds=["fault_reported"]).records)
        assert [r.seq for r in reported] == seqs[:2]

        second_at = stamp_ns(alpha[1].occurred_at)
        since = list(served.history(fault_code="H_ALPHA", since_ns=second_at).records)
        assert [r.seq for r in since] == seqs[1:]
        until = list(served.history(fault_code="H_ALPHA", until_ns=second_at).records)
        assert [r.seq for r in until] == seqs[:1], "until is exclusive"
        window = list(served.history(since_ns=second_at,
                                     until_ns=stamp_ns(alpha[2].occurred_at)).records)
        assert [(r.fault_code, r.seq) for r in window if r.fault_code.startswith("H_")] == [
            ("H_ALPHA", seqs[1]), ("H_BETA", seqs[1] + 1)]

        limited = list(served.history(fault_code="H_ALPHA", limit=1).records)
        assert [r.seq for r in limited] == seqs[:1]
        assert list(served.history(fault_code="H_NEVER_REPORTED").records) == []


# -- tests with a manager of their own (the shared one has stopped by then) ------------------------


# -- list_faults -----------------------------------------------------------------------------------
def test_list_faults_status_and_severity_filters(manager: ManagerFactory,
                                                 client: RosClient) -> None:
    """Every status present at once (conf -2, healing at 2), then every filter."""
    manager("--ros-args", "-p", "confirmation_threshold:=-2", "-p", "healing_enabled:=true",
            "-p", "healing_threshold:=2")
    script: list[tuple[str, int, int]] = [
        ("L_PREFAILED", FAILED, 0),
        ("L_PREPASSED", FAILED, 1), ("L_PREPASSED", PASSED, 0), ("L_PREPASSED", PASSED, 0),
        ("L_CONFIRMED", FAILED, 1), ("L_CONFIRMED", FAILED, 2),
        ("L_CRITICAL", FAILED, 3),
        ("L_HEALED", FAILED, 1), ("L_HEALED", FAILED, 1),
        *[("L_HEALED", PASSED, 0)] * 4,
        ("L_CLEARED", FAILED, 1), ("L_CLEARED", FAILED, 1),
    ]
    for code, event_type, severity in script:
        assert client.report(code, event_type, severity, "", "/list/src"), (code, event_type)
    assert client.clear("L_CLEARED").success
    expected_status = {
        "L_PREFAILED": "PREFAILED", "L_PREPASSED": "PREPASSED", "L_CONFIRMED": "CONFIRMED",
        "L_CRITICAL": "CONFIRMED", "L_HEALED": "HEALED", "L_CLEARED": "CLEARED",
    }
    faults = {code: client.fault(code) for code in expected_status}
    assert {code: f.status for code, f in faults.items()} == expected_status

    def listed(statuses: tuple[str, ...] | list[str] = (), severity: int | None = None
               ) -> list[str]:
        result = client.list_faults(statuses, severity)
        for fault in result:  # the list carries the same full data as get_fault
            assert fault == faults[fault.fault_code]
        return [f.fault_code for f in result]

    assert sorted(listed()) == ["L_CONFIRMED", "L_CRITICAL"]
    assert sorted(listed(["BOGUS"])) == ["L_CONFIRMED", "L_CRITICAL"]
    assert sorted(listed(["confirmed"])) == ["L_CONFIRMED", "L_CRITICAL"]  # unknown string
    for status in ("PREFAILED", "PREPASSED", "HEALED", "CLEARED"):
        assert listed([status]) == [f"L_{status}"], status
    assert sorted(listed(["BOGUS", "HEALED"])) == ["L_HEALED"]
    assert sorted(listed(["PREFAILED", "CONFIRMED"])) == [
        "L_CONFIRMED", "L_CRITICAL", "L_PREFAILED"]
    assert sorted(listed(ALL_STATUSES)) == sorted(expected_status)
    assert listed([], severity=3) == ["L_CRITICAL"]
    assert listed(["CONFIRMED"], severity=2) == ["L_CONFIRMED"]
    assert listed(["CONFIRMED"], severity=1) == []
    # filter_by_severity with severity 0 means "severity 0", not "no filter".
    assert listed(ALL_STATUSES, severity=0) == ["L_PREFAILED"]
    assert sorted(listed(ALL_STATUSES, severity=1)) == ["L_CLEARED", "L_HEALED", "L_PREPASSED"]
    # filter_by_severity false ignores the severity field.
    request = ListFaults.Request(statuses=list(ALL_STATUSES), filter_by_severity=False,
                                 severity=3)
    response = client.call(ListFaults, f"{NS}/list_faults", request)
    assert len(response.faults) == len(expected_status)
    assert (response.muted_count, response.cluster_count) == (0, 0)


def test_ros_parameters_override_the_config_file(manager: ManagerFactory, client: RosClient,
                                                 tmp_path: Path) -> None:
    config = tmp_path / "faultledger.yaml"
    config.write_text("policy:\n  confirmation_threshold: -3\n  healing_enabled: true\n"
                      "  healing_threshold: 1\n", encoding="utf-8")
    manager("--config", str(config), "--ros-args", "-p", "confirmation_threshold:=-2")
    assert client.report("P_CFG", FAILED, 1, "", "/param")
    assert client.fault("P_CFG").status == "PREFAILED"
    assert client.report("P_CFG", FAILED, 1, "", "/param")
    assert client.fault("P_CFG").status == "CONFIRMED", "the ROS parameter (-2) must win"
    for expected in ("CONFIRMED", "CONFIRMED", "HEALED"):  # counter -1, 0, 1 (config: heal 1)
        assert client.report("P_CFG", PASSED, 0, "", "/param")
        assert client.fault("P_CFG").status == expected


def test_ros_parameters_are_sanitised(manager: ManagerFactory, client: RosClient) -> None:
    """A positive confirmation threshold is negated, a negative healing threshold too."""
    manager("--ros-args", "-p", "confirmation_threshold:=3", "-p", "healing_enabled:=true",
            "-p", "healing_threshold:=-1")
    for expected in ("PREFAILED", "PREFAILED", "CONFIRMED"):
        assert client.report("P_SAN", FAILED, 1, "", "/param")
        assert client.fault("P_SAN").status == expected
    for expected in ("CONFIRMED", "CONFIRMED", "CONFIRMED", "HEALED"):  # -2, -1, 0, 1
        assert client.report("P_SAN", PASSED, 0, "", "/param")
        assert client.fault("P_SAN").status == expected


def test_get_history_matches_the_python_api(manager: ManagerFactory, client: RosClient) -> None:
    fault_manager = manager()
    for i in range(5):
        assert client.report(f"HP_{i % 2}", FAILED if i % 3 else PASSED, i % 4, f"d{i}",
                             f"/hp/{i}")
    assert client.clear("HP_0").success
    over_ros = list(client.history().records)
    fault_manager.stop()
    with FaultLedger.open(fault_manager.url, create=False, upgrade=False) as ledger:
        stored = ledger.history()
    assert [(r.seq, r.event_id, r.kind, r.hash) for r in over_ros] == [
        (r.seq, r.event_id, r.kind, r.hash) for r in stored]
    assert [(stamp_ns(r.occurred_at), stamp_ns(r.recorded_at)) for r in over_ros] == [
        (r.occurred_at_ns, r.recorded_at_ns) for r in stored]
    assert [r.fault_code for r in over_ros] == [r.fault_code or "" for r in stored]
    assert [json.loads(r.payload_json) for r in over_ros] == [r.payload for r in stored]


def test_get_history_time_bounds_are_nanosecond_exact(manager: ManagerFactory,
                                                      client: RosClient) -> None:
    """since/until are builtin_interfaces/Time (ns) and bound occurred_at as [since, until)."""
    manager()
    for i in range(3):
        assert client.report("HNS", FAILED, 1, f"r{i}", "/hns")
    records = list(client.history(fault_code="HNS").records)
    assert len(records) == 3
    at = [stamp_ns(r.occurred_at) for r in records]
    middle = at[1]

    def seqs(since_ns: int = 0, until_ns: int = 0) -> list[int]:
        found = client.history(fault_code="HNS", since_ns=since_ns, until_ns=until_ns).records
        return [r.seq for r in found]

    everything = [r.seq for r in records]
    assert seqs(since_ns=middle) == everything[1:]
    assert seqs(since_ns=middle + 1) == everything[2:], (
        f"since = occurred_at + 1 ns must exclude that record (occurred_at {middle})")
    assert seqs(until_ns=middle) == everything[:1]
    assert seqs(until_ns=middle + 1) == everything[:2], (
        f"until = occurred_at + 1 ns must include that record (occurred_at {middle})")
    assert seqs(since_ns=middle, until_ns=middle + 1) == everything[1:2]


def test_database_path_parameter_selects_the_database(manager: ManagerFactory,
                                                      client: RosClient, tmp_path: Path) -> None:
    """medkit's ``database_path`` (a file path) is used when --db is not given."""
    path = tmp_path / "medkit" / "faults.db"
    path.parent.mkdir()
    fault_manager = manager("--ros-args", "-p", f"database_path:={path}", db=path,
                            db_option=False)
    assert str(path) in fault_manager.ready_line
    assert client.report("DBP_1", FAILED, 2, "", "/dbp")
    assert fault_manager.stop() == 0, fault_manager.describe()
    with FaultLedger.open(f"sqlite:///{path}", create=False, upgrade=False) as ledger:
        fault = ledger.get_fault("DBP_1")
    assert fault is not None and fault.severity == 2


# -- lifecycle -------------------------------------------------------------------------------------
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signal_stops_the_manager_cleanly(manager: ManagerFactory, client: RosClient,
                                          sig: signal.Signals) -> None:
    fault_manager = manager()
    assert fault_manager.ready_line.startswith("fault_manager ready")
    assert fault_manager.url in fault_manager.ready_line
    assert client.report("LIFE_1", FAILED, 1, "", "/life")
    assert fault_manager.stop(sig) == 0, fault_manager.describe()
    ready = fault_manager.start()
    assert re.search(r"\bfaults=1\b", ready), ready
    assert client.fault("LIFE_1").status == "CONFIRMED"
    assert fault_manager.stop(sig) == 0, fault_manager.describe()
