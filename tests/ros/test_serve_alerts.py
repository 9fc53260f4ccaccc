"""`faultledger serve` with the config's ``alerts``: the fault manager delivers them on threads
of its own, off the report path (docs/alerts.md). A report made over ROS reaches a webhook
receiver (a threaded http.server on loopback inside the test's network namespace) within a
second; SIGTERM stops the manager (exit 0) and gives the rule's lease up."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import yaml
from tests.fleet_central import wait_for
from tests.http.alert_receiver import alert_receiver

from faultledger import FaultLedger
from faultledger.service import alerts

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient


def test_serve_delivers_a_ros_report_within_a_second_and_stops_cleanly(
        tmp_path: Path, manager: ManagerFactory, client: RosClient) -> None:
    with alert_receiver() as receiver:
        config = tmp_path / "robot.yaml"
        config.write_text(yaml.safe_dump({"robot_id": "robot-ros", "http": {"tokens_file": None},
                                          "alerts": [{"name": "hook", "on": ["fault_confirmed"],
                                                      "receiver": {"type": "webhook",
                                                                   "url": receiver.url}}]}))
        served = manager("--config", str(config))
        assert wait_for(lambda: any(line == f"alerts: hook -> webhook {receiver.url}"
                                    for line in served.stdout_lines), 10), served.describe()
        # Timed from the manager's answering on: the test client's first call would also time
        # its own discovery of the service (about a second on this VM). A PASSED report of a
        # new code confirms nothing, so the receiver gets nothing from it.
        client.wait_until_answering()
        assert client.report("ROS_ALERT_WARM_UP", 1, 3, "from ROS", "/ros/node")
        for number in range(3):
            sent = time.time()
            assert client.report(f"ROS_ALERT_{number}", 0, 3, "from ROS", "/ros/node")
            got = receiver.wait_for(number + 1, timeout=5)
            assert got[-1].body["fault_code"] == f"ROS_ALERT_{number}"
            assert got[-1].body["robot_id"] == "robot-ros"
            assert got[-1].at - sent < 1.0, (number, got[-1].at - sent)
        assert served.stop() == 0, served.describe()
    with FaultLedger.open(f"sqlite:///{served.db_path}", create=False, upgrade=False) as ledger:
        [state] = alerts.rule_states(ledger)
        assert state.counts["delivered"] == 3 and state.holder is None
