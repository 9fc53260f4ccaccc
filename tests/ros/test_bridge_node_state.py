"""node_state bridge end to end: NodeStatePublisher process → bridge process → fault manager.

Every side is a real process: the node (tests/ros/drive_node_state.py, driven over stdin), the
bridge (``faultledger bridge node-state``) and ``faultledger serve``; faults are read back from
the manager's services. Heartbeat timeout 2 s, so a loss shows within a few seconds.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tests.ros.processes import LineProcess

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

DRIVER = str(Path(__file__).with_name("drive_node_state.py"))
DISCOVERY_SEC = 30.0
NODE = "/robot1/lidar_driver"
CODE = "NODE_ROBOT1_LIDAR_DRIVER_"



class Proc(LineProcess):
    def __init__(self, args: list[str], log: Path) -> None:
        super().__init__(args, log, timeout=DISCOVERY_SEC)

    def send(self, command: str) -> None:
        self.write(command)
        self.expect(f"ok {command.split(' ', 1)[0]}", 10.0)



@contextmanager
def running(proc: Proc) -> Iterator[Proc]:
    try:
        yield proc
    finally:
        proc.stop()


def node_process(tmp_path: Path, name: str = "lidar_driver", namespace: str = "/robot1") -> Proc:
    proc = Proc([sys.executable, DRIVER, name, namespace],
                tmp_path / f"node-{time.monotonic_ns()}.log")
    proc.expect("ready ")
    return proc


def bridge_process(tmp_path: Path) -> Proc:
    config = tmp_path / "node_state.yaml"
    config.write_text("heartbeat_timeout_sec: 2.0\ncheck_period_sec: 0.25\n")
    proc = Proc([sys.executable, "-m", "faultledger.cli.main", "bridge", "node-state",
                 "--config", str(config)], tmp_path / "bridge.log")
    proc.expect("bridge ready: node_state")
    return proc


def reports(client: RosClient, code: str) -> list[tuple[str, int, str, str]]:
    """(FAILED/PASSED, severity, source_id, description) of every report of ``code``."""
    out = []
    for record in client.history(fault_code=code, kinds=["fault_reported"]).records:
        payload: dict[str, Any] = json.loads(record.payload_json)
        out.append((payload["event_type"], payload["severity"], payload["source_id"],
                    payload["description"]))
    return out


def kinds(client: RosClient, code: str) -> list[str]:
    return [r[0] for r in reports(client, code)]


def wait_reports(client: RosClient, code: str, expected: list[str],
                 timeout: float = DISCOVERY_SEC) -> None:
    ok = client.spin_until(lambda: kinds(client, code) == expected, timeout)
    assert ok, f"{code}: expected {expected}, got {reports(client, code)}"


def test_node_states_become_faults(tmp_path: Path, manager: ManagerFactory,
                                   client: RosClient) -> None:
    manager()
    with running(bridge_process(tmp_path)) as bridge:
        node = node_process(tmp_path)
        try:
            node.send("running")
            node.send("error E_SCAN scan timeout on /scan")
            wait_reports(client, CODE + "ERROR", ["FAILED"])
            fault = client.fault(CODE + "ERROR")
            assert fault.severity == 2
            assert fault.description == "scan timeout on /scan [E_SCAN]"
            assert list(fault.reporting_sources) == [NODE]
            client.spin_for(2.5)  # a few ERROR heartbeats: edge-triggered, no new report
            node.send("recovering E_SCAN reconnecting")
            node.send("running")
            wait_reports(client, CODE + "ERROR", ["FAILED", "PASSED"])

            node.send("fatal E_MOTOR motor driver dead")
            wait_reports(client, CODE + "FATAL", ["FAILED"])
            assert client.fault(CODE + "FATAL").severity == 3
            assert client.fault(CODE + "FATAL").status == "CONFIRMED"
            node.send("warning W_TEMP motor at 80 C")
            wait_reports(client, CODE + "WARNING", ["FAILED"])
            assert client.fault(CODE + "WARNING").severity == 1
            client.spin_for(1.5)  # the heartbeat after the warning carries FATAL again
            node.send("running")
            wait_reports(client, CODE + "FATAL", ["FAILED", "PASSED"])
            wait_reports(client, CODE + "WARNING", ["FAILED", "PASSED"])
            assert kinds(client, CODE + "ERROR") == ["FAILED", "PASSED"]

            # Bad messages are warned about and ignored.
            node.send("bad 42 /robot1/other")
            node.send("bad 2 ")
            assert client.spin_until(lambda: "unknown state 42" in bridge.log.read_text(), 10.0)
        finally:
            node.stop(signal.SIGKILL)
        # Killed: the heartbeat stops without STOPPING.
        wait_reports(client, CODE + "HEARTBEAT_LOST", ["FAILED"], 20.0)
        lost = client.fault(CODE + "HEARTBEAT_LOST")
        assert lost.severity == 2 and "last state RUNNING" in lost.description

        with running(node_process(tmp_path)) as node:
            wait_reports(client, CODE + "HEARTBEAT_LOST", ["FAILED", "PASSED"])
            node.send("running")
            node.send("stopping")
            node.send("exit")
            assert node.popen.wait(timeout=10) == 0
        client.spin_for(4.0)  # twice the timeout: a clean exit is no loss
        assert kinds(client, CODE + "HEARTBEAT_LOST") == ["FAILED", "PASSED"]
        assert client.get("NODE_ROBOT1_OTHER_ERROR").success is False
        assert bridge.stop() == 0


def test_nodes_view_once_lists_a_running_node(tmp_path: Path) -> None:
    with running(node_process(tmp_path, "camera", "/robot2")) as node:
        node.send("running")
        view = subprocess.run(
            [sys.executable, "-m", "faultledger.cli.main", "nodes", "--once",
             "--listen-sec", "6"], capture_output=True, text=True, timeout=60)
    assert view.returncode == 0, view.stderr
    row = next((line for line in view.stdout.splitlines() if "/robot2/camera" in line), None)
    assert row is not None, view.stdout
    assert "RUNNING" in row and "faultledger_tests" in row and "drive_node_state" in row
