"""The diagnostics bridge's pure logic: levels, codes, filters and the edge trigger (no ROS)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from faultledger.domain.validation import fault_code_error
from faultledger.ros.bridges.codes import fault_code, upper_snake
from faultledger.ros.bridges.diagnostics_mapping import (
    MAX_TRACKED,
    EdgeTracker,
    Report,
    Settings,
    level_of,
)
from faultledger.ros.bridges.settings import normalise, read_yaml

OK, WARN, ERROR, STALE = b"\x00", b"\x01", b"\x02", b"\x03"
BRIDGE = "/faultledger_diagnostics_bridge"


@dataclass
class KV:
    key: str
    value: str


@dataclass
class Status:
    """Shaped like diagnostic_msgs/DiagnosticStatus as rclpy gives it (level as bytes)."""

    name: str
    level: Any = OK
    message: str = ""
    hardware_id: str = ""
    values: list[KV] = field(default_factory=list)


def tracker(**settings: Any) -> tuple[EdgeTracker, list[tuple[str, str]]]:
    warnings: list[tuple[str, str]] = []
    return EdgeTracker(Settings(**settings), BRIDGE,
                       lambda kind, text: warnings.append((kind, text))), warnings


def failed(code: str, severity: int, description: str = "", source: str = BRIDGE) -> Report:
    return Report(False, code, source, severity, description)


def passed(code: str, source: str = BRIDGE) -> Report:
    return Report(True, code, source)


# -- levels and codes ------------------------------------------------------------------------------
@pytest.mark.parametrize(("raw", "level"), [
    (b"\x00", 0), (b"\x01", 1), (b"\x02", 2), (b"\x03", 3), (0, 0), (3, 3),
    (b"\x07", None), (7, None), (-1, None), (b"", None), (b"\x01\x02", None), (True, None),
    ("2", None), (None, None), (bytearray(b"\x02"), 2),
])
def test_levels_arrive_as_bytes_or_int(raw: object, level: int | None) -> None:
    assert level_of(raw) == level


@pytest.mark.parametrize(("name", "code"), [
    ("motor_driver: Temperature", "MOTOR_DRIVER_TEMPERATURE"),
    ("hokuyo_node: Frequency Status", "HOKUYO_NODE_FREQUENCY_STATUS"),
    ("/robot/base: CPU load (%)", "ROBOT_BASE_CPU_LOAD"),
    ("camera.front--left", "CAMERA_FRONT_LEFT"),
    ("MotorDriver GPSStatus", "MOTOR_DRIVER_GPS_STATUS"),
    ("Température moteur", "TEMPERATURE_MOTEUR"),
    ("imu2 x", "IMU2_X"),
    (":::", ""), ("", ""), ("日本", ""),
])
def test_generated_codes_are_upper_snake_case(name: str, code: str) -> None:
    assert upper_snake(name) == code
    if code:
        assert fault_code(name) == code
        assert fault_code_error(code) is None
        t, _ = tracker()
        assert t.code_for(Status(name)) == code


def test_generated_codes_take_the_prefix_and_stay_within_128_characters() -> None:
    t, _ = tracker(code_prefix="DIAG_")
    assert t.code_for(Status("battery: Voltage")) == "DIAG_BATTERY_VOLTAGE"
    long_a, long_b = "x" * 300 + " a", "x" * 300 + " b"
    t, _ = tracker(code_prefix="P.")
    code_a, code_b = t.code_for(Status(long_a)), t.code_for(Status(long_b))
    assert code_a is not None and code_b is not None
    assert len(code_a) == len(code_b) == 128
    assert code_a != code_b and code_a.startswith("P.XXX")
    assert re.fullmatch(r"P\.X+_[0-9A-F]{8}", code_a)  # upper-case hex (lower-case up to 0.1.0)
    assert fault_code_error(code_a) is None and fault_code_error(code_b) is None
    assert t.code_for(Status(long_a)) == code_a  # stable
    assert len(fault_code("x" * 128)) == 128 and fault_code("x" * 128) == "X" * 128


# -- settings --------------------------------------------------------------------------------------
def test_settings_defaults_are_the_documented_ones() -> None:
    s = Settings()
    assert (s.topic, s.name_to_code, s.code_key, s.code_prefix, s.source_from_hardware_id) == \
        ("/diagnostics", {}, "", "", False)
    assert (s.exclude_names, s.include_only_names, s.max_statuses) == ([], [], 1000)
    assert (s.warn_severity, s.error_severity, s.stale_severity) == (1, 2, 3)


def test_bad_settings_fall_back_to_defaults_with_a_warning() -> None:
    warnings: list[str] = []
    s = normalise(Settings, {"topic": "not a topic", "code_prefix": "A B", "stale_severity": 4,
                             "max_statuses": 0, "exclude_names": [""], "warn_severity": 0,
                             "reliability": "sometimes"}, warnings.append, "diagnostics")
    assert (s.topic, s.code_prefix, s.stale_severity, s.max_statuses) == \
        ("/diagnostics", "", 3, 1000)
    assert (s.exclude_names, s.warn_severity, s.reliability) == ([], 0, "reliable")
    assert len(warnings) == 6
    assert any(w.startswith("diagnostics.topic='not a topic' is invalid") for w in warnings)


@pytest.mark.parametrize("topic", ["/diagnostics", "diagnostics", "~/diag", "/a/b_c/d2"])
def test_topic_names(topic: str) -> None:
    assert Settings(topic=topic).topic == topic


def test_an_invalid_mapped_code_is_dropped_with_a_warning() -> None:
    edge, warnings = tracker(name_to_code={"a: b": "GOOD_CODE", "c: d": "bad code"})
    assert edge.process([Status("a: b", ERROR), Status("c: d", ERROR)]) == [
        failed("GOOD_CODE", 2, "a: b [ERROR]"), failed("C_D", 2, "c: d [ERROR]")]
    assert [k for k, _ in warnings] == ["config"]
    assert "name_to_code['c: d']='bad code'" in warnings[0][1]


# -- the edge trigger ------------------------------------------------------------------------------
def test_levels_map_to_severities() -> None:
    edge, _ = tracker()
    reports = edge.process([Status("a", OK), Status("b", WARN, "slow"), Status("c", ERROR),
                            Status("d", STALE)])
    assert reports == [failed("B", 1, "b [WARN]: slow"), failed("C", 2, "c [ERROR]"),
                       failed("D", 3, "d [STALE]")]


def test_configured_severities() -> None:
    edge, _ = tracker(warn_severity=0, error_severity=3, stale_severity=1)
    assert [r.severity for r in edge.process(
        [Status("b", WARN), Status("c", ERROR), Status("d", STALE)])] == [0, 3, 1]


def test_repeated_arrays_report_only_changes() -> None:
    edge, _ = tracker()
    sequence = [OK, OK, WARN, WARN, WARN, ERROR, ERROR, WARN, STALE, OK, OK, ERROR]
    reports = [edge.process([Status("x", level)]) for level in sequence]
    assert [[(r.passed, r.severity) for r in rs] for rs in reports] == [
        [], [], [(False, 1)], [], [], [(False, 2)], [], [(False, 1)], [(False, 3)],
        [(True, 0)], [], [(False, 2)]]
    assert edge.failing == 1


def test_ok_after_failure_is_passed_and_forgotten() -> None:
    edge, _ = tracker()
    edge.process([Status("x", ERROR)])
    assert edge.process([Status("x", OK)]) == [passed("X")]
    assert edge.failing == 0
    assert edge.process([Status("x", OK)]) == []


def test_absent_statuses_change_nothing() -> None:
    edge, _ = tracker()
    edge.process([Status("x", ERROR), Status("y", WARN)])
    assert edge.process([Status("y", WARN)]) == []
    assert edge.process([Status("x", ERROR), Status("y", WARN)]) == []


def test_code_from_values_key_and_passed_to_the_code_that_failed() -> None:
    edge, warnings = tracker(code_key="fault_code")
    assert edge.process([Status("drive", ERROR, values=[KV("fault_code", "E_OVERCURRENT")])]) \
        == [failed("E_OVERCURRENT", 2, "drive [ERROR]")]
    assert edge.process([Status("drive", ERROR, values=[KV("fault_code", "E_OVERCURRENT")])]) \
        == []
    # Another code at the same level: the old one passed, the new one failed.
    assert edge.process([Status("drive", ERROR, values=[KV("fault_code", "E_STALL")])]) == [
        passed("E_OVERCURRENT"), failed("E_STALL", 2, "drive [ERROR]")]
    # OK without the key: PASSED for the code that failed.
    assert edge.process([Status("drive", OK)]) == [passed("E_STALL")]
    # An invalid value falls back to the generated code, with a warning.
    assert edge.process([Status("drive", WARN, values=[KV("fault_code", "E 1")])]) == [
        failed("DRIVE", 1, "drive [WARN]")]
    assert [k for k, _ in warnings] == ["code_value"]


def test_name_to_code_wins_over_the_values_key() -> None:
    edge, _ = tracker(code_key="fault_code", name_to_code={"drive": "DRIVE_FAULT"})
    assert edge.process([Status("drive", ERROR, values=[KV("fault_code", "E_X")])])[0].code \
        == "DRIVE_FAULT"


def test_hardware_id_as_source_and_key() -> None:
    edge, _ = tracker(source_from_hardware_id=True)
    reports = edge.process([Status("imu: Health", ERROR, hardware_id="imu_left"),
                            Status("imu: Health", ERROR, hardware_id="imu_right"),
                            Status("gps", WARN)])
    assert [(r.code, r.source_id) for r in reports] == [
        ("IMU_HEALTH", "imu_left"), ("IMU_HEALTH", "imu_right"), ("GPS", BRIDGE)]
    assert edge.process([Status("imu: Health", OK, hardware_id="imu_left"),
                         Status("imu: Health", ERROR, hardware_id="imu_right")]) == [
        passed("IMU_HEALTH", "imu_left")]


def test_hardware_id_is_only_the_source_when_asked() -> None:
    edge, warnings = tracker()
    reports = edge.process([Status("imu", ERROR, hardware_id="imu_left"),
                            Status("imu", ERROR, hardware_id="imu_right")])
    assert reports == [failed("IMU", 2, "imu [ERROR] (hardware_id: imu_left)")]
    assert [k for k, _ in warnings] == ["duplicate"]


def test_filters_are_unanchored_substrings_and_exclude_wins() -> None:
    edge, _ = tracker(include_only_names=["motor", "battery"], exclude_names=["test"])
    reports = edge.process([Status("left motor: Temp", ERROR), Status("battery", ERROR),
                            Status("camera", ERROR), Status("motor test", ERROR)])
    assert [r.code for r in reports] == ["LEFT_MOTOR_TEMP", "BATTERY"]


def test_bad_statuses_are_warned_about_and_skipped() -> None:
    edge, warnings = tracker()
    reports = edge.process([Status("", ERROR), Status("   ", ERROR), Status("x", b"\x07"),
                            Status("y", 9), Status("z", None), Status("!!!", ERROR),
                            Status("fine", ERROR)])
    assert reports == [failed("FINE", 2, "fine [ERROR]")]
    assert [k for k, _ in warnings] == ["empty_name", "empty_name", "bad_level", "bad_level",
                                        "bad_level", "no_code"]
    assert "unknown level 7" in warnings[2][1]
    # An unknown level leaves the remembered state alone.
    assert edge.process([Status("fine", b"\x07")]) == []
    assert edge.process([Status("fine", ERROR)]) == []


def test_large_arrays_are_cut_at_max_statuses() -> None:
    edge, warnings = tracker(max_statuses=3)
    reports = edge.process([Status(f"s{i}", ERROR) for i in range(5)])
    assert [r.code for r in reports] == ["S0", "S1", "S2"]
    assert warnings[0][0] == "too_many" and "array of 5 statuses" in warnings[0][1]


def test_long_descriptions_are_cut() -> None:
    edge, _ = tracker()
    description = edge.process([Status("x", ERROR, "m" * 10_000)])[0].description
    assert len(description) == 4096 and description.endswith("...")


def test_memory_of_failing_statuses_is_bounded() -> None:
    edge, warnings = tracker(max_statuses=MAX_TRACKED + 5)
    edge.process([Status(f"s{i}", ERROR) for i in range(MAX_TRACKED + 2)])
    assert edge.failing == MAX_TRACKED
    assert [k for k, _ in warnings] == ["tracked", "tracked"]


def test_the_shipped_config_holds_exactly_the_defaults() -> None:
    warnings: list[str] = []
    path = Path(__file__).resolve().parents[1] / "config" / "diagnostics.yaml"
    raw = read_yaml(path)
    assert normalise(Settings, raw, warnings.append) == Settings()
    assert warnings == []
    assert set(raw) == set(Settings.model_fields)
