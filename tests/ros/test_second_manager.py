"""A second ``faultledger serve`` on one ROS graph: refused (exit 2, naming the other), or run
as a read-only ``--follower`` next to the first (docs/ros.md "A second fault manager")."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ros2_medkit_msgs.srv import ClearFault, ListFaults, ReportFault

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

FOLLOWER = "/fault_manager_follower"


def test_a_second_manager_is_refused_naming_the_first(
        tmp_path: Path, manager: ManagerFactory, client: RosClient) -> None:
    manager()
    client.wait_until_answering()

    second = subprocess.run(
        [sys.executable, "-m", "faultledger.cli.main", "serve", "--db",
         str(tmp_path / "other.db")],
        capture_output=True, text=True, timeout=40, cwd=tmp_path,
        env={**os.environ, "FAULTLEDGER_DEBUG": "1"})  # a hang shows where (serve's watchdog)

    assert second.returncode == 2, second.stdout + second.stderr
    assert "fault_manager ready" not in second.stdout
    message = " ".join(second.stderr.split())
    assert "another fault manager already serves /fault_manager/report_fault" in message
    assert "(node /fault_manager, pid unknown)" in message
    assert "--follower" in message and "__ns:=" in message
    assert not (tmp_path / "other.db").exists()  # refused before opening anything


def test_a_follower_serves_reads_and_refuses_writes(
        tmp_path: Path, manager: ManagerFactory, client: RosClient) -> None:
    first = manager()
    client.wait_until_answering()
    assert client.report("SECOND_MANAGER_TEST", severity=3)

    follower = manager("--follower", db=first.db_path)
    assert "follower of /fault_manager (read-only)" in follower.ready_line
    listed = client.call(ListFaults, f"{FOLLOWER}/list_faults",
                         ListFaults.Request(statuses=["CONFIRMED"]), timeout=20.0)
    assert [f.fault_code for f in listed.faults] == ["SECOND_MANAGER_TEST"]
    refused = client.call(ReportFault, f"{FOLLOWER}/report_fault", ReportFault.Request(
        fault_code="VIA_FOLLOWER", event_type=0, severity=1, source_id="/pytest"))
    assert not refused.accepted
    cleared = client.call(ClearFault, f"{FOLLOWER}/clear_fault",
                          ClearFault.Request(fault_code="SECOND_MANAGER_TEST"))
    assert not cleared.success
    assert "read-only follower" in cleared.message
    assert "/fault_manager/clear_fault" in cleared.message
    assert client.get("VIA_FOLLOWER").success is False  # nothing was written
    assert client.fault("SECOND_MANAGER_TEST").status == "CONFIRMED"
    assert follower.stop() == 0
    assert first.running
