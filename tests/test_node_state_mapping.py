"""The node_state bridge's pure mapping: codes, edges and heartbeat timeouts (no ROS)."""

from __future__ import annotations

import pytest

from faultledger.domain.validation import fault_code_error
from faultledger.ros.bridges.codes import fault_code as shared_fault_code
from faultledger.ros.bridges.codes import upper_snake
from faultledger.ros.bridges.node_state_mapping import (
    ERROR,
    FATAL,
    RECOVERING,
    RUNNING,
    STARTING,
    STOPPING,
    WARNING,
    BadMessage,
    NodeStateMonitor,
    Report,
    Severities,
    describe,
)

NODE = "/robot1/lidar_driver"
P = "NODE_ROBOT1_LIDAR_DRIVER_"


def fault_code(nodename: str, suffix: str) -> str:
    """``NODE_<NAME>_<SUFFIX>`` by the bridges' shared rule."""
    return shared_fault_code(nodename, prefix="NODE_", suffix=suffix)


def failed(suffix: str, severity: int, description: str, node: str = NODE) -> Report:
    return Report("failed", fault_code(node, suffix), node, severity, description)


def passed(suffix: str, node: str = NODE) -> Report:
    return Report("passed", fault_code(node, suffix), node)


def codes(reports: list[Report]) -> list[tuple[str, str]]:
    return [(r.kind, r.code) for r in reports]


# -- codes -----------------------------------------------------------------------------------------
@pytest.mark.parametrize(("nodename", "name"), [
    ("/robot1/lidar_driver", "ROBOT1_LIDAR_DRIVER"),
    ("/talker", "TALKER"),
    ("lidar", "LIDAR"),
    ("/a//b-c.d", "A_B_C_D"),
    ("/ümlaut/node", "UMLAUT_NODE"),  # "MLAUT_NODE" up to 0.1.0
    ("/robot1/lidarDriver", "ROBOT1_LIDAR_DRIVER"),  # "ROBOT1_LIDARDRIVER" up to 0.1.0
    ("/", ""),
    ("", ""),
])
def test_node_names_are_upper_snake_case(nodename: str, name: str) -> None:
    assert upper_snake(nodename) == name
    if name:
        m = NodeStateMonitor()
        assert m.on_message(nodename, ERROR, 0.0)[0].code == f"NODE_{name}_ERROR"


def test_codes_are_valid_and_long_names_are_cut_with_a_hash() -> None:
    assert fault_code(NODE, "ERROR") == "NODE_ROBOT1_LIDAR_DRIVER_ERROR"
    long_a = "/fleet/" + "x" * 200 + "/a"
    long_b = "/fleet/" + "x" * 200 + "/b"
    for suffix in ("ERROR", "FATAL", "WARNING", "HEARTBEAT_LOST"):
        for name in (long_a, long_b, NODE):
            code = fault_code(name, suffix)
            assert len(code) <= 128 and fault_code_error(code) is None, code
    assert fault_code(long_a, "HEARTBEAT_LOST") != fault_code(long_b, "HEARTBEAT_LOST")
    assert len(fault_code(long_a, "HEARTBEAT_LOST")) == 128
    assert len(fault_code(long_a, "ERROR")) == 128
    # the codes of one long node share its hash (the cut name is longer for a shorter suffix)
    digest = fault_code(long_a, "HEARTBEAT_LOST")[-len("12345678_HEARTBEAT_LOST"):][:8]
    assert fault_code(long_a, "ERROR").endswith(f"_{digest}_ERROR")


def test_description_carries_both_messages() -> None:
    assert describe("lidar lost", "E42") == "lidar lost [E42]"
    assert describe("", "E42") == "E42"
    assert describe("text", "") == "text"
    assert len(describe("x" * 5000, "")) == 4096


# -- state machine ---------------------------------------------------------------------------------
def test_error_is_edge_triggered_and_running_passes_it() -> None:
    m = NodeStateMonitor(5.0)
    assert m.on_message(NODE, STARTING, 0.0) == []
    assert m.on_message(NODE, RUNNING, 1.0) == []
    assert m.on_message(NODE, ERROR, 1.5, machine_message="E1", human_message="scan lost") == \
        [failed("ERROR", 2, "scan lost [E1]")]
    assert m.on_message(NODE, ERROR, 2.5, machine_message="E1", human_message="scan lost") == []
    assert m.on_message(NODE, RECOVERING, 3.0) == []
    assert m.on_message(NODE, RUNNING, 3.5) == [passed("ERROR")]
    assert m.on_message(NODE, RUNNING, 4.5) == []
    # a new entry into ERROR is a new occurrence
    assert codes(m.on_message(NODE, ERROR, 5.0)) == [("failed", P + "ERROR")]
    assert codes(m.on_message(NODE, RECOVERING, 5.5)) == []
    assert codes(m.on_message(NODE, ERROR, 6.0)) == [("failed", P + "ERROR")]


def test_fatal_and_warning_are_raised_and_passed_together() -> None:
    m = NodeStateMonitor(5.0, Severities(error=2, fatal=3, warning=0, heartbeat_lost=1))
    m.on_message(NODE, RUNNING, 0.0)
    assert m.on_message(NODE, FATAL, 1.0, human_message="motor dead") == \
        [failed("FATAL", 3, "motor dead")]
    assert m.on_message(NODE, WARNING, 1.2, human_message="hot") == [failed("WARNING", 0, "hot")]
    # the heartbeat after a warning carries FATAL again: not a new entry
    assert m.on_message(NODE, FATAL, 2.0, human_message="motor dead") == []
    assert m.on_message(NODE, RUNNING, 3.0) == [passed("FATAL"), passed("WARNING")]


def test_a_warning_while_running_is_passed_by_the_next_running_heartbeat() -> None:
    m = NodeStateMonitor(5.0)
    m.on_message(NODE, RUNNING, 0.0)
    assert codes(m.on_message(NODE, WARNING, 0.5, machine_message="w")) == \
        [("failed", P + "WARNING")]
    assert m.nodes[NODE].state == RUNNING
    assert m.on_message(NODE, RUNNING, 1.0) == [passed("WARNING")]
    assert codes(m.on_message(NODE, WARNING, 1.5)) == [("failed", P + "WARNING")]
    assert codes(m.on_message(NODE, WARNING, 1.6)) == [("failed", P + "WARNING")]
    assert m.on_message(NODE, RUNNING, 2.0) == [passed("WARNING")]


def test_heartbeat_loss_after_the_timeout_and_heal_on_return() -> None:
    m = NodeStateMonitor(2.0)
    m.on_message(NODE, RUNNING, 10.0)
    assert m.check(11.0) == []
    assert m.check(12.0) == []  # exactly the timeout: not yet
    lost = m.check(12.01)
    assert lost == [failed("HEARTBEAT_LOST", 2,
                           f"no heartbeat from {NODE} for 2 s (last state RUNNING)")]
    assert m.check(20.0) == []  # once per silence
    # back (a restarted node starts in STARTING): healed at once, RUNNING has nothing left
    assert m.on_message(NODE, STARTING, 21.0) == [passed("HEARTBEAT_LOST")]
    assert m.on_message(NODE, RUNNING, 21.5) == []
    assert m.check(23.4) == []
    assert codes(m.check(23.6)) == [("failed", P + "HEARTBEAT_LOST")]


def test_lost_while_in_error_keeps_the_error_raised_until_running() -> None:
    m = NodeStateMonitor(1.0)
    m.on_message(NODE, ERROR, 0.0)
    assert codes(m.check(1.5)) == [("failed", P + "HEARTBEAT_LOST")]
    # back still in ERROR: the loss heals, the error is not re-reported
    assert codes(m.on_message(NODE, ERROR, 2.0)) == [("passed", P + "HEARTBEAT_LOST")]
    assert codes(m.on_message(NODE, RUNNING, 2.5)) == [("passed", P + "ERROR")]


def test_stopping_then_silence_is_a_clean_exit() -> None:
    m = NodeStateMonitor(1.0)
    m.on_message(NODE, RUNNING, 0.0)
    m.on_message(NODE, STOPPING, 0.5)
    assert m.check(100.0) == []
    # it comes back later: watched again
    assert m.on_message(NODE, STARTING, 101.0) == []
    assert codes(m.check(102.5)) == [("failed", P + "HEARTBEAT_LOST")]


def test_a_warning_after_stopping_does_not_arm_the_timeout() -> None:
    m = NodeStateMonitor(1.0)
    m.on_message(NODE, STOPPING, 0.0)
    m.on_message(NODE, WARNING, 0.1)
    assert m.check(10.0) == []


def test_nodes_are_independent() -> None:
    other = "/arm/controller"
    m = NodeStateMonitor(1.0)
    m.on_message(NODE, ERROR, 0.0)
    m.on_message(other, RUNNING, 0.0)
    m.on_message(other, RUNNING, 1.8)
    assert codes(m.check(1.9)) == [("failed", P + "HEARTBEAT_LOST")]
    assert m.on_message(other, RUNNING, 2.0) == []
    assert [r.source_id for r in m.on_message(other, FATAL, 2.1)] == [other]


@pytest.mark.parametrize(("nodename", "state"), [("", RUNNING), ("/", RUNNING), (NODE, 42),
                                                  (NODE, 7), (NODE, -1)])
def test_bad_messages_raise_and_change_nothing(nodename: str, state: int) -> None:
    m = NodeStateMonitor(1.0)
    m.on_message(NODE, RUNNING, 0.0)
    with pytest.raises(BadMessage):
        m.on_message(nodename, state, 0.9)
    assert m.nodes[NODE].last_seen == 0.0 and m.nodes[NODE].state == RUNNING
    assert set(m.nodes) == {NODE}
