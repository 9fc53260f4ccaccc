"""Action-status bridge with real processes: status publishers (drive_action_server.py), the
bridge (standalone ``faultledger bridge action-status`` or inside ``faultledger serve``) and the
fault manager; results are read from the manager's services.

The "action servers" publish GoalStatusArray on ``/<action>/_action/status`` themselves, as
rcl_action does (see drive_action_server.py), so they can also send arrays no real server would.
Real rclpy ActionServers (with an action type built for the tests) and goal outcomes:
test_goal_outcomes.py.
"""

from __future__ import annotations

import json
import sys
import time
import uuid
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml
from tests.ros.processes import LineProcess

from faultledger.ros.bridges.action_status_mapping import (
    STATUS_ABORTED,
    STATUS_CANCELED,
    STATUS_EXECUTING,
    STATUS_SUCCEEDED,
    STATUS_UNKNOWN,
)
from faultledger.ros.bridges.codes import MAX_CODE_LENGTH, fault_code

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

DRIVER = Path(__file__).with_name("drive_action_server.py")
DISCOVERY_SEC = 30.0



class Proc(LineProcess):
    stop_wait_sec = 15.0

    def __init__(self, args: list[str], log: Path) -> None:
        super().__init__(args, log, timeout=DISCOVERY_SEC)




class Driver(Proc):
    """drive_action_server.py: one node publishing status arrays for any number of actions."""

    def __init__(self, tmp_path: Path, name: str, namespace: str = "/") -> None:
        super().__init__([sys.executable, str(DRIVER), name, "--ros-args", "-r",
                          f"__ns:={namespace}"], tmp_path / f"driver-{name}.log")
        self.count = 0
        self.expect("driver ready")

    def send(self, *command: Any) -> None:
        self.count += 1
        self.ask(list(command), f"ok {self.count}", 10.0)

    def exit(self) -> int:
        """EOF: the driver destroys its node and exits; its actions vanish from the graph."""
        assert self.popen.stdin is not None
        self.popen.stdin.close()
        return self.popen.wait(timeout=15)


def goal_uuid(n: int) -> str:
    return str(uuid.UUID(bytes=n.to_bytes(16, "big")))


def wait_for(what: str, predicate: Callable[[], bool], timeout: float = DISCOVERY_SEC,
              why: Callable[[], str] = lambda: "") -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            raise AssertionError(f"not within {timeout} s: {what}\n{why()}")
        time.sleep(0.1)


def reports(client: RosClient, code: str) -> list[tuple[str, str]]:
    """(FAILED|PASSED, source_id) of each report of ``code`` in the manager's history."""
    records = client.history(fault_code=code, kinds=["fault_reported"]).records
    return [(json.loads(r.payload_json)["event_type"], r.source_id) for r in records]


def has_reports(client: RosClient, code: str, expected: list[tuple[str, str]]) -> bool:
    return reports(client, code) == expected


def codes_now(client: RosClient) -> set[str]:
    statuses = ["PREFAILED", "PREPASSED", "CONFIRMED", "HEALED", "CLEARED"]
    return {f.fault_code for f in client.list_faults(statuses)}


def test_standalone_bridge_turns_status_arrays_into_edges(
        manager: ManagerFactory, client: RosClient, tmp_path: Path) -> None:
    fm = manager(start=False)  # started once the bridge has a report to deliver
    config = tmp_path / "action_status.yaml"
    config.write_text(yaml.safe_dump({
        "rescan_period_sec": 0.5,
        "include_only_actions": ["robot1"],
        "exclude_actions": ["ignored"],
        "dedup_capacity": -5,  # invalid: normalised to 4096 with a warning, never fatal
    }))
    server = Driver(tmp_path, "nav_server", "/robot1")
    bridge = Proc([sys.executable, "-m", "faultledger.cli.main", "bridge", "action-status",
                   "--config", str(config)], tmp_path / "bridge.log")
    try:
        bridge.expect("bridge ready: action_status as /faultledger_action_status_bridge")
        source = "/robot1/nav_server"
        nav = "ACTION_ROBOT1_NAVIGATE_TO_POSE_ABORTED"
        path = "ACTION_ROBOT1_FOLLOW_PATH_ABORTED"
        bad = "ACTION_ROBOT1_BAD_ABORTED"
        long_action = ("/robot1/joint_trajectory_controller_of_the_left_arm_of_the_robot_on_the_"
                       "mobile_base_of_cell_four/follow_joint_trajectory_with_tolerances")
        long_code = fault_code(long_action, prefix="ACTION_", suffix="ABORTED")

        def saw(text: str) -> Callable[[], bool]:
            return lambda: text in bridge.stderr()

        # A publisher whose QoS cannot match reliable + transient_local: a warning, not silence.
        server.send("open", "/robot1/legacy", "volatile")
        server.send("goals", "/robot1/legacy", [[1, STATUS_ABORTED]])
        # Two goals in one array, ABORTED before SUCCEEDED: failed whatever the order.
        server.send("goals", "/robot1/navigate_to_pose",
                    [[1, STATUS_ABORTED], [2, STATUS_SUCCEEDED]])
        # Raised while no fault manager runs: the reporter retries until one answers.
        wait_for("raised", saw(f"{nav} FAILED"), why=bridge.stderr)
        fm.start()
        # Filtered out (exclude wins; include_only needs "robot1"); CANCELED is no fault here.
        server.send("goals", "/robot1/ignored_action", [[1, STATUS_ABORTED]])
        server.send("goals", "/robot2/spin", [[1, STATUS_ABORTED]])
        server.send("goals", "/robot1/dock", [[1, STATUS_CANCELED]])
        server.send("goals", long_action, [[1, STATUS_ABORTED]])
        wait_for(f"{nav} reported", lambda: reports(client, nav) == [("FAILED", source)],
                 why=bridge.stderr)
        fault = client.fault(nav)
        assert (fault.status, fault.severity, fault.occurrence_count) == ("CONFIRMED", 2, 1)
        assert fault.description == \
            f"action /robot1/navigate_to_pose: goal {goal_uuid(1)} ABORTED"
        assert list(fault.reporting_sources) == [source]

        # A retry loop as a server publishes it (finished goals stay in the array): abort,
        # abort, succeed → one FAILED; judged on the whole array (the default), the success
        # does not heal while the aborted goals are still in it ...
        for goal, outcome in ((1, STATUS_ABORTED), (2, STATUS_ABORTED), (3, STATUS_SUCCEEDED)):
            server.send("goals", "/robot1/follow_path", [[goal, STATUS_EXECUTING]])
            server.send("goals", "/robot1/follow_path", [[goal, outcome]])
            wait_for(f"goal {goal} seen", saw(
                f"action /robot1/follow_path: goal {goal_uuid(goal)} "
                f"{'SUCCEEDED' if outcome == STATUS_SUCCEEDED else 'ABORTED'}"),
                why=bridge.stderr)
        wait_for(f"{path} raised", lambda: reports(client, path) == [("FAILED", source)])
        # ... but once the server has forgotten them (its result_timeout).
        server.send("raw", "/robot1/follow_path", [[3, STATUS_SUCCEEDED]])
        wait_for(f"{path} healed",
                 lambda: reports(client, path) == [("FAILED", source), ("PASSED", source)])

        # Bad messages: empty arrays and values outside GoalStatus change nothing, crash nothing.
        server.send("raw", "/robot1/bad", [])
        server.send("raw", "/robot1/bad", [[1, 42], [2, STATUS_UNKNOWN]])
        wait_for("status 42 warned about", saw(
            f"action /robot1/bad: goal {goal_uuid(1)} INVALID(42): not a GoalStatus value"),
            why=bridge.stderr)
        server.send("raw", "/robot1/bad", [])
        server.send("goals", "/robot1/bad", [[3, STATUS_ABORTED]])
        wait_for(f"{bad} reported", lambda: reports(client, bad) == [("FAILED", source)])

        # A name too long for 128 characters: cut, hashed, suffix kept.
        assert len(long_code) == MAX_CODE_LENGTH and long_code.endswith("_ABORTED")
        assert long_code.startswith("ACTION_ROBOT1_JOINT_TRAJECTORY_CONTROLLER_")
        wait_for(f"{long_code} reported", lambda: reports(client, long_code) == [
            ("FAILED", source)])
        assert client.fault(long_code).description.startswith(f"action {long_action}: goal ")

        assert codes_now(client) == {nav, path, bad, long_code}
        log = bridge.stderr()
        assert "action /robot1/ignored_action is filtered out" in log
        assert "action /robot2/spin is filtered out" in log
        assert "action_status.dedup_capacity=-5 is invalid" in log
        assert "action /robot1/legacy: a status publisher offers QoS incompatible" in log

        # The server exits: its actions vanish; the failed ones are healed first.
        assert server.exit() == 0
        healed = [("FAILED", source), ("PASSED", source)]
        for code in (nav, bad, long_code):
            wait_for(f"{code} healed on vanish", partial(has_reports, client, code, healed),
                     why=bridge.stderr)
        wait_for("vanished logged", saw("action /robot1/follow_path vanished"))
        assert reports(client, path) == [("FAILED", source), ("PASSED", source)]
        assert bridge.popen.poll() is None
    finally:
        server.stop()
        assert bridge.stop() == 0


def test_bridge_inside_serve_judging_new_goals_with_canceled_as_fault_and_no_healing(
        manager: ManagerFactory, client: RosClient, tmp_path: Path) -> None:
    config = tmp_path / "serve.yaml"
    config.write_text(yaml.safe_dump({"bridges": {"action_status": {
        "enabled": True, "rescan_period_sec": 0.5, "canceled_is_fault": True,
        "heal_on_succeeded": False, "code_prefix": "NAV", "aborted_severity": 3,
        "judge": "new_goals",  # the goals stay in the array: judged by what changed
    }}}))
    fm = manager("--config", str(config))
    server = Driver(tmp_path, "dock_server")
    try:
        canceled, aborted = "NAV_DOCK_CANCELED", "NAV_DOCK_ABORTED"
        source = "/dock_server"
        server.send("goals", "/dock", [[1, STATUS_EXECUTING]])
        server.send("goals", "/dock", [[1, STATUS_CANCELED]])
        wait_for(f"{canceled} reported", lambda: reports(client, canceled) == [
            ("FAILED", source)], why=fm.describe)
        fault = client.fault(canceled)
        assert (fault.status, fault.severity) == ("CONFIRMED", 3)
        assert fault.description == f"action /dock: goal {goal_uuid(1)} CANCELED"
        # Healthy again without a PASSED (healing off); the next cancel is a new edge.
        server.send("goals", "/dock", [[2, STATUS_SUCCEEDED]])
        wait_for("success seen", lambda: f"goal {goal_uuid(2)} SUCCEEDED" in fm.stderr_text(),
                 why=fm.describe)
        server.send("goals", "/dock", [[3, STATUS_CANCELED]])
        wait_for("second cancel reported", lambda: reports(client, canceled) == [
            ("FAILED", source), ("FAILED", source)], why=fm.describe)
        # An abort while failed because of a cancel is its own fault.
        server.send("goals", "/dock", [[4, STATUS_ABORTED]])
        wait_for(f"{aborted} reported", lambda: reports(client, aborted) == [
            ("FAILED", source)], why=fm.describe)
        assert server.exit() == 0
        wait_for("vanished", lambda: "action /dock vanished" in fm.stderr_text(),
                 why=fm.describe)
        assert reports(client, canceled) == [("FAILED", source), ("FAILED", source)]
        assert reports(client, aborted) == [("FAILED", source)]
        assert fm.running
    finally:
        server.stop()
