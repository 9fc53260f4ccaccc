"""Hardware status bridge end to end, each side its own process, no fakes (SPEC §8).

A hardware publisher process (``drive_hardware_status.py``) republishes its current
``HardwareStatus`` on /hardware_status every 50 ms like ros2_control's status publisher; the
bridge runs as ``python -m faultledger.cli.main bridge hardware-status --config FILE``; the
faults are read from the real fault manager (``faultledger serve``). One manager, bridge and
publisher serve the whole class; every test uses its own hardware id.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from tests.ros.processes import LineProcess

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

HERE = Path(__file__).parent
BRIDGE_FQN = "/faultledger_hardware_status_bridge"
WAIT_SEC = 30.0
EMERGENCY_STOP_HW, HEALTH_OK, HEALTH_ERROR = 5, 1, 4

CONFIG = {
    "topics": ["/hardware_status"],
    "discover": False,
    "warn_interval_sec": 0.5,
    "max_devices": 8,
    "severities": {"health_error": 2, "canopen_emcy": 1, "emergency_stop": "loud"},
}



class Proc(LineProcess):
    """A bridge or publisher; ``stop(None)`` only closes stdin, which ends the publisher."""

    close_stdin_on_stop = True

    def __init__(self, args: list[str], log: Path) -> None:
        super().__init__(args, log, timeout=WAIT_SEC)



@dataclass
class Rig:
    client: RosClient
    bridge: Proc
    publisher: Proc

    def show(self, spec: dict[str, Any], ticks: int = 3) -> None:
        """Publish ``spec`` from now on, and wait until it went out ``ticks`` more times."""
        self.publisher.ask({"set": spec}, "set")
        self.publisher.ask({"ticks": ticks}, "ticked")

    def reports(self, code: str) -> list[dict[str, Any]]:
        """Payloads of every report of ``code`` the ledger holds, in log order."""
        response = self.client.history(fault_code=code, kinds=["fault_reported"])
        assert response.success, response.error_message
        return [json.loads(record.payload_json) for record in response.records]

    def wait_reports(self, code: str, count: int) -> list[dict[str, Any]]:
        """The reports of ``code`` once there are ``count``, plus a settle time in which no
        extra one may arrive (the bridge's reports are asynchronous)."""
        reports: list[dict[str, Any]] = []

        def enough() -> bool:
            reports[:] = self.reports(code)
            return len(reports) >= count

        assert self.client.spin_until(enough, WAIT_SEC), (
            f"{code}: {len(reports)} reports, expected {count}; {reports}\nbridge stderr:\n"
            f"{self.bridge.log.read_text()[-3000:]}")
        self.client.spin_for(1.0)
        return self.reports(code)


@pytest.fixture(scope="class")
def rig(shared_manager: ManagerFactory, shared_client: RosClient,
        tmp_path_factory: pytest.TempPathFactory) -> Iterator[Rig]:
    directory = tmp_path_factory.mktemp("hardware_status")
    shared_manager()
    config = directory / "hardware_status.yaml"
    config.write_text(yaml.safe_dump(CONFIG))
    bridge = Proc([sys.executable, "-m", "faultledger.cli.main", "bridge", "hardware-status",
                   "--config", str(config)], directory / "bridge.log")
    publisher = Proc([sys.executable, str(HERE / "drive_hardware_status.py"), "0.05"],
                     directory / "publisher.log")
    try:
        bridge.expect("bridge ready: hardware_status as " + BRIDGE_FQN)
        publisher.expect("matched")
        yield Rig(shared_client, bridge, publisher)
    finally:
        publisher.stop()
        assert bridge.stop() == 0, bridge.log.read_text()[-3000:]


def generic_device(device_id: str, **state: Any) -> dict[str, Any]:
    return {"id": device_id, "generic": [state]}


class TestHardwareStatusBridge:
    def test_five_estop_presses_are_five_failed_and_five_passed(self, rig: Rig) -> None:
        code = "HW_CELL1_ARM_CONTROLLER_SAFETY_IO_EMERGENCY_STOP"
        pressed = {"hw": "cell1/arm_controller",
                   "devices": [generic_device("safetyIO", errors=[EMERGENCY_STOP_HW])]}
        released = {"hw": "cell1/arm_controller", "devices": [generic_device("safetyIO")]}
        rig.show(released)
        for _ in range(5):
            rig.show(pressed, ticks=4)  # the status is repeated while the button is held
            rig.show(released, ticks=3)
        reports = rig.wait_reports(code, 10)
        assert [r["event_type"] for r in reports] == ["FAILED", "PASSED"] * 5
        # emergency_stop: "loud" is invalid: warned about, the default 3 (CRITICAL) is used.
        assert {r["severity"] for r in reports if r["event_type"] == "FAILED"} == {3}
        assert {r["source_id"] for r in reports} == {"cell1/arm_controller"}
        fault = rig.client.fault(code)
        # CRITICAL confirms at once; healing is off, so releases never heal it, and a press
        # after a release is another FAILED of the same fault, not a new occurrence.
        assert (fault.status, fault.severity, fault.occurrence_count) == ("CONFIRMED", 3, 1)
        assert list(fault.reporting_sources) == ["cell1/arm_controller"]
        assert "severities.emergency_stop='loud' is invalid" in rig.bridge.log.read_text()

    def test_health_error_entering_and_leaving(self, rig: Rig) -> None:
        code = "HW_GRIPPER_FINGER_HEALTH_ERROR"
        rig.show({"hw": "gripper", "devices": [generic_device("finger", health=HEALTH_OK)]})
        rig.show({"hw": "gripper", "devices": [generic_device(
            "finger", health=HEALTH_ERROR, details={"temperature": "92C"})]})
        rig.show({"hw": "gripper", "devices": [generic_device("finger", health=HEALTH_OK)]})
        reports = rig.wait_reports(code, 2)
        assert [(r["event_type"], r["severity"]) for r in reports] == [("FAILED", 2),
                                                                       ("PASSED", 0)]
        fault = rig.client.fault(code)
        assert "health ERROR" in fault.description and "temperature=92C" in fault.description

    def test_ethercat_error_names_the_al_status_code(self, rig: Rig) -> None:
        code = "HW_BASE_WHEEL_LEFT_ETHERCAT_ERROR"
        ok = {"position": 2, "al_state": 8}
        bad = {"position": 2, "al_state": 4, "has_error": True, "al_status_code": 0x1B}
        rig.show({"hw": "base", "devices": [{"id": "wheel_left", "ethercat": [ok]}]})
        rig.show({"hw": "base", "devices": [{"id": "wheel_left", "ethercat": [bad]}]})
        rig.show({"hw": "base", "devices": [{"id": "wheel_left", "ethercat": [ok]}]})
        reports = rig.wait_reports(code, 2)
        assert [r["event_type"] for r in reports] == ["FAILED", "PASSED"]
        assert "al_status_code 0x001B" in reports[0]["description"]
        assert "slave 2" in reports[0]["description"]

    def test_canopen_emcy(self, rig: Rig) -> None:
        code = "HW_LIFT_MOTOR_CANOPEN_EMCY_8130"
        rig.show({"hw": "lift", "devices": [{"id": "motor", "canopen": [{"node": 5}]}]})
        rig.show({"hw": "lift", "devices": [{"id": "motor",
                                             "canopen": [{"node": 5, "emcy": 0x8130}]}]})
        reports = rig.wait_reports(code, 1)
        assert [(r["event_type"], r["severity"]) for r in reports] == [("FAILED", 1)]
        assert "CANopen node 5 EMCY 0x8130" in reports[0]["description"]
        rig.show({"hw": "lift", "devices": [{"id": "motor", "canopen": [{"node": 5}]}]})
        assert [r["event_type"] for r in rig.wait_reports(code, 2)] == ["FAILED", "PASSED"]

    def test_bad_messages_are_survived(self, rig: Rig) -> None:
        # Empty hardware id, empty device id, unknown enum values, too many devices.
        rig.show({"hw": "", "devices": [generic_device("j", health=HEALTH_ERROR)]})
        rig.show({"hw": "junk", "extra_devices": 300, "devices": [
            generic_device("", health=HEALTH_ERROR),
            generic_device("weird", health=200, power=99, connect=77, errors=[250]),
        ]})
        # The bridge is alive and still maps: the unknown values left 'weird' untouched.
        rig.show({"hw": "junk", "devices": [generic_device("weird", errors=[EMERGENCY_STOP_HW])]})
        reports = rig.wait_reports("HW_JUNK_WEIRD_EMERGENCY_STOP", 1)
        assert [r["event_type"] for r in reports] == ["FAILED"]
        assert rig.bridge.popen.poll() is None
        faults = {f.fault_code for f in rig.client.list_faults(["CONFIRMED", "PREFAILED"])}
        assert not any(c.startswith("HW__") or "WEIRD_HEALTH" in c or c.startswith("HW_JUNK_X")
                       for c in faults), faults
        log = rig.bridge.log.read_text()
        for text in ("empty hardware_id", "empty device_id", "unknown health_status value 200",
                     "unknown power_state value 99", "unknown connectivity_status value 77",
                     "unknown error_domain value 250", "302 devices; only the first 8"):
            assert text in log, text
