"""Diagnostics bridge end to end, each side its own process, no fakes (SPEC §8).

A publisher process (``drive_diagnostics.py``) republishes its current DiagnosticArray on
/diagnostics every 0.2 s like a diagnostic_updater; the bridge runs as
``python -m faultledger.cli.main bridge diagnostics --config FILE``; the faults are read from the
real fault manager (``faultledger serve``). One manager, bridge and publisher serve the whole
class; every test uses its own status names.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from tests.ros.processes import LineProcess

from faultledger.ros.bridges.codes import fault_code

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

HERE = Path(__file__).parent
BRIDGE_FQN = "/faultledger_diagnostics_bridge"
DISCOVERY_SEC = 30.0
WAIT_SEC = 20.0
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LONG_NAME = "very long sensor name " * 10

CONFIG = {
    "name_to_code": {"lidar: Status": "LIDAR_FAILURE"},
    "code_key": "fault_code",
    "source_from_hardware_id": True,
    "exclude_names": ["ignored"],
    "warn_interval_sec": 1.0,
    "max_statuses": 0,  # invalid: warned about, the default 1000 is used
}



class Proc(LineProcess):
    """A bridge or publisher; ``stop(None)`` only closes stdin, which ends the publisher."""

    close_stdin_on_stop = True

    def __init__(self, args: list[str], log: Path) -> None:
        super().__init__(args, log, timeout=WAIT_SEC)



@dataclass
class Rig:
    client: RosClient
    publisher: Proc
    bridge: Proc | None = None  # None: the bridge runs inside the manager

    def publish(self, *statuses: dict[str, Any]) -> None:
        """From now on the publisher repeats exactly these statuses."""
        self.publisher.ask({"set": list(statuses)}, "set ")

    def ticks(self, n: int) -> None:
        """Wait until the current array was published ``n`` more times."""
        self.publisher.ask({"ticks": n}, "ticked")

    def reports(self, code: str) -> list[tuple[str, int, str]]:
        """(event_type, severity, source_id) of every report of ``code`` the ledger holds."""
        response = self.client.history(fault_code=code, kinds=["fault_reported"])
        assert response.success, response.error_message
        out = []
        for record in response.records:
            payload = json.loads(record.payload_json)
            out.append((payload["event_type"], payload["severity"], payload["source_id"]))
        return out

    def wait(self, what: Callable[[], bool], message: str, timeout: float = WAIT_SEC) -> None:
        deadline = time.monotonic() + timeout
        while not what():
            if time.monotonic() >= deadline:
                log = self.bridge.log.read_text()[-4000:] if self.bridge else "(in serve)"
                raise AssertionError(f"{message} within {timeout} s; bridge stderr:\n{log}")
            time.sleep(0.2)

    def wait_reports(self, code: str, count: int) -> list[tuple[str, int, str]]:
        """The reports of ``code`` once there are ``count`` of them."""
        self.wait(lambda: len(self.reports(code)) >= count, f"{code}: no {count} reports")
        return self.reports(code)

    def settle(self) -> None:
        """Give repeated publications time to cause (wrong) reports: 5 more arrays, then the
        reporter's delivery."""
        self.ticks(5)
        time.sleep(1.0)

    def absent(self, code: str) -> bool:
        return not self.client.get(code).success


def status(name: str, level: int, message: str = "", hardware_id: str = "",
           **values: str) -> dict[str, Any]:
    return {"name": name, "level": level, "message": message, "hardware_id": hardware_id,
            "values": values}


@pytest.fixture(scope="class")
def rig(shared_manager: ManagerFactory, shared_client: RosClient,
        tmp_path_factory: pytest.TempPathFactory) -> Iterator[Rig]:
    directory = tmp_path_factory.mktemp("diagnostics")
    shared_manager()
    config = directory / "diagnostics.yaml"
    config.write_text(yaml.safe_dump(CONFIG))
    bridge = Proc([sys.executable, "-m", "faultledger.cli.main", "bridge", "diagnostics",
                   "--config", str(config)], directory / "bridge.log")
    publisher = Proc([sys.executable, str(HERE / "drive_diagnostics.py"), "0.2"],
                     directory / "publisher.log")
    try:
        assert bridge.expect("bridge ready", DISCOVERY_SEC) == \
            f"bridge ready: diagnostics as {BRIDGE_FQN}"
        publisher.expect("matched", DISCOVERY_SEC)
        yield Rig(shared_client, publisher, bridge)
    finally:
        assert publisher.stop(None) == 0, publisher.log.read_text()[-4000:]
        assert bridge.stop() == 0, bridge.log.read_text()[-4000:]


class TestDiagnosticsBridge:
    def test_levels_map_to_severities_once_each(self, rig: Rig) -> None:
        rig.publish(status("levels: Ok", OK), status("levels: Warn", WARN, "fan slow"),
                    status("levels: Error", ERROR), status("levels: Stale", STALE),
                    status("ignored: Error", ERROR))
        for code, severity in [("LEVELS_WARN", 1), ("LEVELS_ERROR", 2), ("LEVELS_STALE", 3)]:
            assert rig.wait_reports(code, 1) == [("FAILED", severity, BRIDGE_FQN)]
        rig.settle()
        for code, severity in [("LEVELS_WARN", 1), ("LEVELS_ERROR", 2), ("LEVELS_STALE", 3)]:
            assert rig.reports(code) == [("FAILED", severity, BRIDGE_FQN)]
            fault = rig.client.fault(code)
            assert (fault.severity, fault.status) == (severity, "CONFIRMED")
            assert list(fault.reporting_sources) == [BRIDGE_FQN]
        assert rig.client.fault("LEVELS_WARN").description == "levels: Warn [WARN]: fan slow"
        assert rig.absent("LEVELS_OK")  # first sight of OK reports nothing
        assert rig.absent("IGNORED_ERROR")  # exclude_names

    def test_periodic_repetition_reports_once(self, rig: Rig) -> None:
        rig.publish(status("motor_driver: Temperature", ERROR, "winding at 140 C"))
        assert rig.wait_reports("MOTOR_DRIVER_TEMPERATURE", 1) == [("FAILED", 2, BRIDGE_FQN)]
        rig.ticks(10)  # ten more identical arrays
        time.sleep(1.0)
        assert len(rig.reports("MOTOR_DRIVER_TEMPERATURE")) == 1

    def test_level_changes_are_reported(self, rig: Rig) -> None:
        code = "BATTERY_VOLTAGE"
        expected: list[tuple[str, int, str]] = []
        for level, report in [(WARN, ("FAILED", 1)), (ERROR, ("FAILED", 2)),
                              (STALE, ("FAILED", 3)), (OK, ("PASSED", 0)),
                              (WARN, ("FAILED", 1))]:
            rig.publish(status("battery: Voltage", level))
            expected.append((*report, BRIDGE_FQN))
            assert rig.wait_reports(code, len(expected)) == expected
            rig.ticks(3)  # the same level again: nothing new
        rig.settle()
        assert rig.reports(code) == expected
        assert rig.client.fault(code).severity == 3  # the manager never lowers severity

    def test_codes_from_map_values_and_names_and_hardware_sources(self, rig: Rig) -> None:
        long_code = fault_code(LONG_NAME)
        assert len(long_code) == 128
        rig.publish(
            status("lidar: Status", ERROR, hardware_id=""),  # name_to_code; no hardware_id
            status("can_bus: Node 3", WARN, hardware_id="can0", fault_code="CAN_NODE3_TIMEOUT"),
            status("imu: Health", ERROR, hardware_id="imu_left"),
            status("imu: Health", ERROR, hardware_id="imu_right"),
            status("joint: Encoder", ERROR, fault_code="not valid!"),  # falls back to the name
            status(LONG_NAME, ERROR),
        )
        assert rig.wait_reports("LIDAR_FAILURE", 1) == [("FAILED", 2, BRIDGE_FQN)]
        assert rig.wait_reports("CAN_NODE3_TIMEOUT", 1) == [("FAILED", 1, "can0")]
        imu = rig.wait_reports("IMU_HEALTH", 2)
        assert sorted(imu) == [("FAILED", 2, "imu_left"), ("FAILED", 2, "imu_right")]
        assert rig.wait_reports("JOINT_ENCODER", 1) == [("FAILED", 2, BRIDGE_FQN)]
        assert rig.wait_reports(long_code, 1) == [("FAILED", 2, BRIDGE_FQN)]
        assert rig.absent("LIDAR_STATUS") and rig.absent("CAN_BUS_NODE_3")
        # Back to OK without the value: PASSED goes to the code that failed, from its source.
        rig.publish(status("can_bus: Node 3", OK, hardware_id="can0"))
        assert rig.wait_reports("CAN_NODE3_TIMEOUT", 2)[1] == ("PASSED", 0, "can0")
        rig.settle()
        assert len(rig.reports("CAN_NODE3_TIMEOUT")) == 2
        assert rig.bridge is not None
        assert "fault_code='not valid!' is not a valid fault code" in rig.bridge.log.read_text()

    def test_bad_messages_are_warned_about_and_survived(self, rig: Rig) -> None:
        bulk = [status(f"bulk: {i}", ERROR if i in (5, 1200) else OK) for i in range(1500)]
        rig.publish(status("", ERROR), status("weird: Level", 7), status(":::", ERROR), *bulk)
        assert rig.wait_reports("BULK_5", 1) == [("FAILED", 2, BRIDGE_FQN)]
        rig.settle()
        assert rig.absent("BULK_1200")  # beyond max_statuses
        assert rig.absent("WEIRD_LEVEL")
        assert rig.bridge is not None and rig.bridge.popen.poll() is None
        rig.publish(status("after: Bad Input", ERROR))
        assert rig.wait_reports("AFTER_BAD_INPUT", 1) == [("FAILED", 2, BRIDGE_FQN)]
        log = rig.bridge.log.read_text()
        for text in ["max_statuses=0 is invalid", "array of 1503 statuses",
                     "status with an empty name", "unknown level 7",
                     "':::' has no letter or digit"]:
            assert text in log, f"{text!r} not in the bridge's log:\n{log[-4000:]}"


def test_inside_serve_with_inline_settings(manager: ManagerFactory, client: RosClient,
                                           tmp_path: Path) -> None:
    """``faultledger serve`` starts the bridge from its config's ``bridges:`` section."""
    config = tmp_path / "faultledger.yaml"
    config.write_text(yaml.safe_dump({"bridges": {"diagnostics": {
        "enabled": True, "code_prefix": "DIAG_", "include_only_names": ["wheel"]}}}))
    manager("--config", str(config))
    publisher = Proc([sys.executable, str(HERE / "drive_diagnostics.py"), "0.2"],
                     tmp_path / "publisher.log")
    try:
        publisher.expect("matched", DISCOVERY_SEC)
        rig = Rig(client, publisher)
        rig.publish(status("left wheel: Current", ERROR), status("arm: Current", ERROR))
        assert rig.wait_reports("DIAG_LEFT_WHEEL_CURRENT", 1) == [("FAILED", 2, BRIDGE_FQN)]
        rig.publish(status("left wheel: Current", OK), status("arm: Current", ERROR))
        assert rig.wait_reports("DIAG_LEFT_WHEEL_CURRENT", 2)[1] == ("PASSED", 0, BRIDGE_FQN)
        assert rig.absent("DIAG_ARM_CURRENT")
    finally:
        assert publisher.stop(None) == 0, publisher.log.read_text()[-4000:]
