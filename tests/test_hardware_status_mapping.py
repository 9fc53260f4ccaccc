"""The hardware-status mapping (pure): each condition's entry and exit, edge triggering, codes,
severities from settings, bad messages. The ROS side is tests/ros/test_bridge_hardware_status.py.
"""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from faultledger.domain.validation import fault_code_error
from faultledger.ros.bridges import hardware_status_mapping as m
from faultledger.ros.bridges.codes import fault_code, upper_snake
from faultledger.ros.bridges.hardware_status_mapping import (
    CONDITIONS,
    HardwareStatusMapper,
    Settings,
    Severities,
    Transition,
    resolve_severities,
)

DOC = Path(__file__).resolve().parents[1] / "docs" / "bridges" / "hardware_status.md"


def generic(health: int = m.HEALTH_OK, errors: tuple[int, ...] = (), power: int = m.POWER_ON,
            connect: int = m.CONNECT_UP, **extra: Any) -> SimpleNamespace:
    return SimpleNamespace(health_status=health, error_domain=list(errors), operational_mode=2,
                           power_state=power, connectivity_status=connect, manufacturer="",
                           model="", firmware_version="", state_details=[], **extra)


def device(device_id: str = "joint1", generic_states: list[Any] | None = None,
           canopen: list[Any] | None = None, ethercat: list[Any] | None = None,
           vda: list[Any] | None = None) -> SimpleNamespace:
    return SimpleNamespace(device_id=device_id, generic_hardware_status=generic_states or [],
                           canopen_states=canopen or [], ethercat_states=ethercat or [],
                           vda5050_states=vda or [])


def status(*devices: Any, hardware_id: str = "arm") -> SimpleNamespace:
    return SimpleNamespace(hardware_id=hardware_id, hardware_device_states=list(devices))


def mapper(**settings: Any) -> HardwareStatusMapper:
    severities = settings.pop("severities", {})
    return HardwareStatusMapper(Settings(**settings), Severities(**severities))


def summary(transitions: list[Transition]) -> list[tuple[str, str, int]]:
    return [(t.code, "FAILED" if t.failed else "PASSED", t.severity) for t in transitions]


def run(mp: HardwareStatusMapper, message: Any) -> list[tuple[str, str, int]]:
    transitions, _ = mp.update(message)
    return summary(transitions)


# -- each condition: entry and exit ---------------------------------------------------------------
CASES = [
    ("EMERGENCY_STOP", generic(errors=(m.EMERGENCY_STOP_HW,)), 3),
    ("EMERGENCY_STOP_SW", generic(errors=(m.EMERGENCY_STOP_SW,)), 3),
    ("PROTECTIVE_STOP", generic(errors=(m.PROTECTIVE_STOP_HW,)), 2),
    ("PROTECTIVE_STOP_SW", generic(errors=(m.PROTECTIVE_STOP_SW,)), 2),
    ("SAFETY_STOP", generic(errors=(m.SAFETY_STOP,)), 2),
    ("ERROR_UNKNOWN", generic(errors=(m.ERROR_UNKNOWN,)), 2),
    ("ERROR_HW", generic(errors=(m.ERROR_HW,)), 2),
    ("ERROR_SW", generic(errors=(m.ERROR_SW,)), 2),
    ("OVER_TRAVEL", generic(errors=(m.ERROR_OVER_TRAVEL,)), 2),
    ("CALIBRATION_REQUIRED", generic(errors=(m.CALIBRATION_REQUIRED,)), 1),
    ("HEALTH_ERROR", generic(health=m.HEALTH_ERROR), 2),
    ("HEALTH_ERROR", generic(health=m.HEALTH_FATAL), 3),
    ("POWER_ERROR", generic(power=m.POWER_ERROR), 2),
    ("BATTERY_LOW", generic(power=m.POWER_LEVEL_LOW), 1),
    ("BATTERY_CRITICAL", generic(power=m.POWER_LEVEL_CRITICAL), 2),
    ("CHARGING_ERROR", generic(power=m.POWER_CHARGING_ERROR), 1),
    ("CONNECTION_LOST", generic(connect=m.CONNECT_DOWN), 2),
    ("CONNECTION_LOST", generic(connect=m.CONNECT_FAILURE), 2),
    ("CONNECTION_SLOW", generic(connect=m.CONNECTION_SLOW), 1),
]


@pytest.mark.parametrize(("suffix", "bad", "severity"), CASES)
def test_each_generic_condition_fails_on_entry_and_passes_on_exit(
        suffix: str, bad: Any, severity: int) -> None:
    mp = mapper()
    code = f"HW_ARM_JOINT1_{suffix}"
    assert run(mp, status(device(generic_states=[generic()]))) == []
    assert run(mp, status(device(generic_states=[bad]))) == [(code, "FAILED", severity)]
    assert run(mp, status(device(generic_states=[bad]))) == []
    assert run(mp, status(device(generic_states=[generic()]))) == [(code, "PASSED", 0)]
    assert run(mp, status(device(generic_states=[generic()]))) == []


def test_ethercat_error_carries_the_al_status_code() -> None:
    mp = mapper()
    ok = SimpleNamespace(slave_position=3, vendor_id="0x2", product_code="0x1", al_state=8,
                         has_error=False, al_status_code=0)
    bad = SimpleNamespace(slave_position=3, vendor_id="0x2", product_code="0x1", al_state=4,
                          has_error=True, al_status_code=0x001B)
    assert run(mp, status(device("drive", ethercat=[ok]))) == []
    transitions, _ = mp.update(status(device("drive", ethercat=[bad])))
    assert summary(transitions) == [("HW_ARM_DRIVE_ETHERCAT_ERROR", "FAILED", 2)]
    assert "al_status_code 0x001B" in transitions[0].description
    assert "slave 3" in transitions[0].description and "SAFEOP" in transitions[0].description
    assert run(mp, status(device("drive", ethercat=[bad]))) == []
    assert run(mp, status(device("drive", ethercat=[ok]))) == [
        ("HW_ARM_DRIVE_ETHERCAT_ERROR", "PASSED", 0)]


def canopen(emcy: int = 0, dsp: int = 4, nmt: int = 5) -> SimpleNamespace:
    return SimpleNamespace(node_id=7, nmt_state=nmt, dsp_402_state=dsp, last_emcy_code=emcy)


def test_canopen_emcy_code_per_emcy_value_and_drive_fault() -> None:
    mp = mapper()
    assert run(mp, status(device("wheel", canopen=[canopen()]))) == []
    transitions, _ = mp.update(status(device("wheel", canopen=[canopen(0x8130)])))
    assert summary(transitions) == [("HW_ARM_WHEEL_CANOPEN_EMCY_8130", "FAILED", 2)]
    assert "EMCY 0x8130" in transitions[0].description and "node 7" in transitions[0].description
    assert run(mp, status(device("wheel", canopen=[canopen(0x8130)]))) == []
    # Another EMCY: the first one ends, the new one begins.
    assert run(mp, status(device("wheel", canopen=[canopen(0x2310)]))) == [
        ("HW_ARM_WHEEL_CANOPEN_EMCY_2310", "FAILED", 2),
        ("HW_ARM_WHEEL_CANOPEN_EMCY_8130", "PASSED", 0)]
    assert run(mp, status(device("wheel", canopen=[canopen(0, dsp=m.DSP402_FAULT)]))) == [
        ("HW_ARM_WHEEL_CANOPEN_DRIVE_FAULT", "FAILED", 2),
        ("HW_ARM_WHEEL_CANOPEN_EMCY_2310", "PASSED", 0)]
    assert run(mp, status(device("wheel", canopen=[canopen()]))) == [
        ("HW_ARM_WHEEL_CANOPEN_DRIVE_FAULT", "PASSED", 0)]


def test_vda5050_error() -> None:
    mp = mapper()
    ok = SimpleNamespace(error_type="", error_description="")
    bad = SimpleNamespace(error_type="orderError", error_description="node 4 unknown")
    assert run(mp, status(device("agv", vda=[ok]))) == []
    transitions, _ = mp.update(status(device("agv", vda=[bad])))
    assert summary(transitions) == [("HW_ARM_AGV_VDA5050_ERROR", "FAILED", 2)]
    assert "orderError: node 4 unknown" in transitions[0].description
    assert run(mp, status(device("agv", vda=[ok]))) == [("HW_ARM_AGV_VDA5050_ERROR", "PASSED", 0)]


# -- edge triggering -------------------------------------------------------------------------------
def test_five_presses_with_repeats_are_five_failed_and_five_passed() -> None:
    mp = mapper()
    pressed = status(device(generic_states=[generic(errors=(m.EMERGENCY_STOP_HW,))]))
    released = status(device(generic_states=[generic()]))
    seen: list[tuple[str, str, int]] = []
    for _ in range(5):
        for _ in range(4):
            seen += run(mp, pressed)
        for _ in range(3):
            seen += run(mp, released)
    assert seen == [("HW_ARM_JOINT1_EMERGENCY_STOP", "FAILED", 3),
                    ("HW_ARM_JOINT1_EMERGENCY_STOP", "PASSED", 0)] * 5


def test_conditions_are_independent_per_condition_device_and_hardware() -> None:
    mp = mapper()
    both = generic(errors=(m.EMERGENCY_STOP_HW, m.PROTECTIVE_STOP_HW), health=m.HEALTH_ERROR)
    assert sorted(run(mp, status(device("a", [both]), device("b", [both])))) == sorted(
        (f"HW_ARM_{d}_{s}", "FAILED", sev) for d in "AB"
        for s, sev in (("EMERGENCY_STOP", 3), ("PROTECTIVE_STOP", 2), ("HEALTH_ERROR", 2)))
    only_estop = generic(errors=(m.EMERGENCY_STOP_HW,))
    assert run(mp, status(device("a", [only_estop]), device("b", [both]))) == [
        ("HW_ARM_A_PROTECTIVE_STOP", "PASSED", 0), ("HW_ARM_A_HEALTH_ERROR", "PASSED", 0)]
    assert run(mp, status(device("a", [both]), hardware_id="base")) == [
        ("HW_BASE_A_EMERGENCY_STOP", "FAILED", 3), ("HW_BASE_A_PROTECTIVE_STOP", "FAILED", 2),
        ("HW_BASE_A_HEALTH_ERROR", "FAILED", 2)]


def test_a_missing_device_or_block_assumes_nothing() -> None:
    mp = mapper()
    pressed = generic(errors=(m.EMERGENCY_STOP_HW,))
    assert run(mp, status(device("a", [pressed]), device("b", [generic()]))) == [
        ("HW_ARM_A_EMERGENCY_STOP", "FAILED", 3)]
    assert run(mp, status(device("b", [generic()]))) == []  # device a gone: still held
    assert run(mp, status()) == []
    assert mp.held("arm", "a") == {"EMERGENCY_STOP": 3}
    # Only EtherCAT this time: the generic conditions are not evaluated.
    ok = SimpleNamespace(slave_position=0, al_state=8, has_error=False, al_status_code=0)
    assert run(mp, status(device("a", ethercat=[ok]))) == []
    assert run(mp, status(device("a", [generic()]))) == [("HW_ARM_A_EMERGENCY_STOP", "PASSED", 0)]
    assert mp.held("arm", "a") == {}


def test_severity_rise_while_held_is_reported_again_but_a_fall_is_not() -> None:
    mp = mapper()
    code = "HW_ARM_JOINT1_HEALTH_ERROR"
    assert run(mp, status(device(generic_states=[generic(health=m.HEALTH_ERROR)]))) == [
        (code, "FAILED", 2)]
    assert run(mp, status(device(generic_states=[generic(health=m.HEALTH_FATAL)]))) == [
        (code, "FAILED", 3)]
    assert run(mp, status(device(generic_states=[generic(health=m.HEALTH_ERROR)]))) == []
    assert run(mp, status(device(generic_states=[generic(health=m.HEALTH_WARNING)]))) == [
        (code, "PASSED", 0)]


def test_several_generic_entries_are_combined() -> None:
    mp = mapper()
    states = [generic(health=m.HEALTH_ERROR), generic(health=m.HEALTH_FATAL,
                                                       errors=(m.ERROR_HW,))]
    assert sorted(run(mp, status(device(generic_states=states)))) == [
        ("HW_ARM_JOINT1_ERROR_HW", "FAILED", 2), ("HW_ARM_JOINT1_HEALTH_ERROR", "FAILED", 3)]


def test_control_msgs_earlier_field_name_hardware_status_is_read() -> None:
    mp = mapper()
    dev = SimpleNamespace(device_id="j", hardware_status=[generic(errors=(m.EMERGENCY_STOP_HW,))])
    assert run(mp, status(dev)) == [("HW_ARM_J_EMERGENCY_STOP", "FAILED", 3)]


# -- codes -----------------------------------------------------------------------------------------
def test_upper_snake() -> None:
    assert upper_snake("left_arm/wheelMotor-1") == "LEFT_ARM_WHEEL_MOTOR_1"
    assert upper_snake("RRBot") == "RR_BOT"  # "RRBOT" up to 0.1.0 (acronyms were not split)
    assert upper_snake("  joint 1 ") == "JOINT_1"
    assert upper_snake("Motör") == "MOTOR"  # "MOT_R" up to 0.1.0 (accents were not dropped)
    assert upper_snake("/") == ""


def code(prefix: str, hardware_id: str, device_id: str, suffix: str) -> str:
    """What the mapper reports: ``<PREFIX>_<HW>_<DEVICE>_<SUFFIX>`` (shared rule)."""
    return fault_code(hardware_id, device_id, prefix=f"{prefix}_" if prefix else "",
                      suffix=suffix)


def test_codes_are_valid_bounded_and_distinct() -> None:
    assert code("HW", "pal_arm", "base_motor", "EMERGENCY_STOP") == \
        "HW_PAL_ARM_BASE_MOTOR_EMERGENCY_STOP"
    assert code("", "arm", "j1", "ERROR_HW") == "ARM_J1_ERROR_HW"
    long_a = code("HW", "h" * 200, "device_a", "CANOPEN_EMCY_8130")
    long_b = code("HW", "h" * 200, "device_b", "CANOPEN_EMCY_8130")
    for c in (long_a, long_b):
        assert len(c) == 128
        assert c.endswith("_CANOPEN_EMCY_8130")
        assert fault_code_error(c) is None
    assert long_a != long_b
    assert fault_code_error(code("HW", "ä..ö", "../x", "SAFETY_STOP")) is None


def test_an_id_without_letters_or_digits_gets_a_hash() -> None:
    """Up to 0.1.0 such an id became ``ID_<6 hex>`` in place; now the code is hashed."""
    slash = code("HW", "/", "motor", "SAFETY_STOP")
    assert re.fullmatch(r"HW_MOTOR_[0-9A-F]{8}_SAFETY_STOP", slash)
    assert slash != code("HW", "//", "motor", "SAFETY_STOP")
    assert slash != code("HW", "motor", "/", "SAFETY_STOP")


def test_the_mapper_reports_the_shared_codes() -> None:
    dev = device("wheelMotor", [generic(errors=(m.EMERGENCY_STOP_HW,))])
    mp = mapper(code_prefix="hw")
    transitions, _ = mp.update(status(dev, hardware_id="left_arm"))
    assert [t.code for t in transitions] == ["HW_LEFT_ARM_WHEEL_MOTOR_EMERGENCY_STOP"]
    assert transitions[0].code == code("HW", "left_arm", "wheelMotor", "EMERGENCY_STOP")
    transitions, _ = mapper(code_prefix="").update(status(dev, hardware_id="h" * 200))
    assert transitions[0].code == code("", "h" * 200, "wheelMotor", "EMERGENCY_STOP")


def test_source_id_is_the_hardware_id_or_the_override() -> None:
    msg = status(device(generic_states=[generic(errors=(m.EMERGENCY_STOP_HW,))]), hardware_id="rb")
    assert mapper().update(msg)[0][0].source_id == "rb"
    assert mapper(source_id="/robot/arm").update(msg)[0][0].source_id == "/robot/arm"


def test_code_prefix_setting() -> None:
    msg = status(device(generic_states=[generic(errors=(m.EMERGENCY_STOP_HW,))]))
    assert run(mapper(code_prefix="R2"), msg) == [("R2_ARM_JOINT1_EMERGENCY_STOP", "FAILED", 3)]


# -- severities from settings ---------------------------------------------------------------------
def test_severities_from_settings_with_bad_values_falling_back() -> None:
    warnings: list[str] = []
    severities = resolve_severities(
        {"emergency_stop": 2, "health_fatal": 9, "no_such": 1}, warnings.append)
    assert severities.emergency_stop == 2
    assert severities.health_fatal == 3
    assert any("health_fatal=9" in w for w in warnings)
    assert any("no_such" in w for w in warnings)
    mp = HardwareStatusMapper(Settings(), severities)
    assert run(mp, status(device(generic_states=[generic(errors=(m.EMERGENCY_STOP_HW,))]))) == [
        ("HW_ARM_JOINT1_EMERGENCY_STOP", "FAILED", 2)]


def test_every_severity_setting_is_used_by_a_condition_and_documented() -> None:
    keys = set(Severities.model_fields)
    used = {k.strip() for c in CONDITIONS for k in c.severity_key.split("/")}
    assert used == keys
    doc = DOC.read_text(encoding="utf-8")
    for condition in CONDITIONS:
        assert f"`{condition.suffix}`" in doc, condition.suffix
    for key, info in Severities.model_fields.items():
        assert f"`{key}`" in doc and f"| {info.default} |" in doc, key


# -- bad messages ---------------------------------------------------------------------------------
def test_empty_ids_are_ignored_with_warnings() -> None:
    mp = mapper()
    transitions, warnings = mp.update(status(device(generic_states=[generic(health=4)]),
                                             hardware_id=""))
    assert transitions == [] and [k for k, _ in warnings] == ["empty_hardware_id"]
    transitions, warnings = mp.update(status(device("", [generic(health=4)]),
                                             device("ok", [generic(health=4)])))
    assert summary(transitions) == [("HW_ARM_OK_HEALTH_ERROR", "FAILED", 2)]
    assert [k for k, _ in warnings] == ["empty_device_id:arm"]


def test_unknown_enum_values_are_ignored_and_keep_the_state() -> None:
    mp = mapper()
    assert run(mp, status(device(generic_states=[generic(health=m.HEALTH_ERROR)]))) == [
        ("HW_ARM_JOINT1_HEALTH_ERROR", "FAILED", 2)]
    transitions, warnings = mp.update(status(device(generic_states=[
        generic(health=77, power=200, connect=99, errors=(250, m.EMERGENCY_STOP_HW))],
        canopen=[canopen(dsp=42, nmt=3)])))
    assert summary(transitions) == [("HW_ARM_JOINT1_EMERGENCY_STOP", "FAILED", 3)]
    assert sorted(k.split(":")[1] for k, _ in warnings) == [
        "connectivity_status", "dsp_402_state", "error_domain", "health_status", "nmt_state",
        "power_state"]
    assert mp.held("arm", "joint1") == {"HEALTH_ERROR": 2, "EMERGENCY_STOP": 3}


def test_huge_arrays_are_truncated_with_a_warning() -> None:
    mp = mapper(max_devices=3, max_entries=2)
    devices = [device(f"d{i}", [generic(errors=(m.ERROR_HW,) * 50)]) for i in range(10)]
    transitions, warnings = mp.update(status(*devices))
    assert [t.device_id for t in transitions] == ["d0", "d1", "d2"]
    assert "too_many:devices:arm" in [k for k, _ in warnings]
    assert any(k.startswith("too_many:error_domain") for k, _ in warnings)


def test_duplicate_devices_and_garbage_fields_do_not_crash() -> None:
    mp = mapper()
    weird = SimpleNamespace(device_id="j", generic_hardware_status=None, canopen_states="xx",
                            ethercat_states=5)
    transitions, warnings = mp.update(status(weird, weird))
    assert transitions == [] and [k for k, _ in warnings] == ["duplicate_device:arm"]
    transitions, warnings = mp.update(SimpleNamespace())
    assert transitions == [] and [k for k, _ in warnings] == ["empty_hardware_id"]


def test_hardware_ids_tracked_are_bounded() -> None:
    mp = mapper(max_hardware=2)
    msg = [generic(errors=(m.ERROR_HW,))]
    assert len(run(mp, status(device("d", msg), hardware_id="a"))) == 1
    assert len(run(mp, status(device("d", msg), hardware_id="b"))) == 1
    transitions, warnings = mp.update(status(device("d", msg), hardware_id="c"))
    assert transitions == [] and [k for k, _ in warnings] == ["max_hardware"]


def test_real_message_classes_are_read_by_field_name() -> None:
    msgs = pytest.importorskip("hardware_status_msgs.msg")
    state = msgs.GenericState(health_status=msgs.GenericState.HEALTH_OK,
                              error_domain=[msgs.GenericState.EMERGENCY_STOP_HW])
    ecat = msgs.EtherCATState(has_error=True, al_status_code=0x1B, al_state=4)
    dev = msgs.HardwareDeviceStatus(device_id="j1", generic_hardware_status=[state],
                                    ethercat_states=[ecat],
                                    canopen_states=[msgs.CANopenState(last_emcy_code=0x8130)])
    message = msgs.HardwareStatus(hardware_id="arm", hardware_device_states=[dev])
    assert sorted(run(mapper(), message)) == [
        ("HW_ARM_J1_CANOPEN_EMCY_8130", "FAILED", 2), ("HW_ARM_J1_EMERGENCY_STOP", "FAILED", 3),
        ("HW_ARM_J1_ETHERCAT_ERROR", "FAILED", 2)]
