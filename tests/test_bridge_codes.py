"""The bridges' one fault-code rule (``faultledger.ros.bridges.codes``): properties and the
documented examples of every bridge (docs/bridges/*.md)."""

from __future__ import annotations

import hashlib
import re

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from faultledger.domain.validation import fault_code_error
from faultledger.ros.bridges.codes import (
    HASH_LENGTH,
    MAX_CODE_LENGTH,
    UPPER_SNAKE,
    fault_code,
    name_hash,
    upper_snake,
)

CODE = re.compile(r"^[A-Z0-9]+(_[A-Z0-9]+)*$")

names = st.text(max_size=300)
snake = st.from_regex(UPPER_SNAKE, fullmatch=True).filter(lambda s: len(s) <= 24)
prefixes = st.one_of(st.just(""), snake.map(lambda s: s + "_"))
suffixes = st.one_of(st.just(""), snake)


@settings(max_examples=200)
@given(st.lists(names, min_size=1, max_size=3), prefixes, suffixes)
def test_a_code_is_upper_snake_bounded_and_keeps_prefix_and_suffix(
        parts: list[str], prefix: str, suffix: str) -> None:
    code = fault_code(*parts, prefix=prefix, suffix=suffix)
    assert CODE.match(code), code
    assert len(code) <= MAX_CODE_LENGTH
    assert fault_code_error(code) is None
    assert code.startswith(prefix)
    if suffix:
        assert code.endswith("_" + suffix)


@settings(max_examples=300)
@given(names)
def test_upper_snake_is_upper_snake_or_empty(text: str) -> None:
    result = upper_snake(text)
    assert result == "" or CODE.match(result), result
    # Not idempotent: "0a" → "0A", but "0A" → "0_A" (a digit before a capital is a camel split).


@settings(max_examples=300)
@given(st.text(alphabet="abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=100))
def test_a_short_snake_case_name_is_just_upper_cased(name: str) -> None:
    cleaned = re.sub("_+", "_", name).strip("_")
    if cleaned:
        assert fault_code(name, prefix="P_", suffix="S") == f"P_{cleaned.upper()}_S"


@settings(max_examples=100)
@given(st.text(max_size=200), st.text(max_size=200), suffixes)
def test_two_different_long_names_get_different_codes(a: str, b: str, suffix: str) -> None:
    assume(a != b)
    head = "x" * 150  # both codes are cut: only the hash tells them apart
    one, two = head + a, head + b
    assert fault_code(one, suffix=suffix) != fault_code(two, suffix=suffix)
    assert fault_code(one, prefix="P_", suffix=suffix).startswith("P_XXXX")


@settings(max_examples=200)
@given(st.text(min_size=130, max_size=400), suffixes)
def test_a_long_name_ends_in_the_hash_of_the_full_text_before_the_suffix(
        name: str, suffix: str) -> None:
    code = fault_code(name, prefix="NODE_", suffix=suffix)
    digest = hashlib.sha256(name.encode("utf-8", "surrogatepass")).hexdigest()
    hashed = digest[:HASH_LENGTH].upper()
    assert hashed == name_hash(name)
    tail = f"_{suffix}" if suffix else ""
    if len(f"NODE_{upper_snake(name)}{tail}") > MAX_CODE_LENGTH or not upper_snake(name):
        assert code.endswith(f"{hashed}{tail}"), code
    else:
        assert code == f"NODE_{upper_snake(name)}{tail}"


def test_lone_surrogates_are_hashed_not_refused() -> None:
    code = fault_code("\ud800" * 10, suffix="ERROR")
    assert re.fullmatch(r"[0-9A-F]{8}_ERROR", code)


def test_an_empty_name_gets_the_hash_alone() -> None:
    assert fault_code("/", prefix="ACTION_", suffix="ABORTED") == \
        f"ACTION_{name_hash('/')}_ABORTED"
    assert fault_code(":::") == name_hash(":::")
    assert fault_code("/") != fault_code("//")


def test_several_names_hash_unambiguously() -> None:
    long = "x" * 200
    assert fault_code(long + "a", "b", suffix="S") != fault_code(long, "ab", suffix="S")
    assert fault_code("/", "a", suffix="S") != fault_code("a", "/", suffix="S")


def test_exactly_the_maximum_is_not_hashed() -> None:
    name = "a" * (MAX_CODE_LENGTH - len("P__S"))
    assert fault_code(name, prefix="P_", suffix="S") == f"P_{name.upper()}_S"
    longer = fault_code(name + "a", prefix="P_", suffix="S")
    assert len(longer) == MAX_CODE_LENGTH
    assert longer.endswith(f"_{name_hash(name + 'a')}_S")


def test_a_prefix_and_suffix_leaving_room_for_the_hash_alone() -> None:
    prefix = "P" * (MAX_CODE_LENGTH - HASH_LENGTH - len("_S"))
    code = fault_code("some name", prefix=prefix, suffix="S")
    assert code == f"{prefix}{name_hash('some name')}_S" and len(code) == MAX_CODE_LENGTH


def test_a_prefix_and_suffix_without_room_are_refused() -> None:
    with pytest.raises(ValueError, match="no room"):
        fault_code("x", prefix="P" * 100, suffix="S" * 30)


# The documented short-name examples of each bridge keep their codes.
@pytest.mark.parametrize(("names", "prefix", "suffix", "code"), [
    # docs/bridges/action_status.md
    (("/navigate_to_pose",), "ACTION_", "ABORTED", "ACTION_NAVIGATE_TO_POSE_ABORTED"),
    (("/robot1/arm/follow_joint_trajectory",), "ACTION_", "CANCELED",
     "ACTION_ROBOT1_ARM_FOLLOW_JOINT_TRAJECTORY_CANCELED"),
    (("/robot/moveGroup",), "ACTION_", "ABORTED", "ACTION_ROBOT_MOVE_GROUP_ABORTED"),
    (("camelCase",), "ACTION_", "ABORTED", "ACTION_CAMEL_CASE_ABORTED"),
    # docs/bridges/diagnostics.md (no suffix; the prefix is used as given)
    (("motor_driver: Temperature",), "", "", "MOTOR_DRIVER_TEMPERATURE"),
    (("/robot/base: CPU load (%)",), "", "", "ROBOT_BASE_CPU_LOAD"),
    (("GPSStatus",), "", "", "GPS_STATUS"),
    (("Température moteur",), "", "", "TEMPERATURE_MOTEUR"),
    (("battery: Voltage",), "DIAG_", "", "DIAG_BATTERY_VOLTAGE"),
    # docs/bridges/hardware_status.md
    (("pal_arm", "base_motor"), "HW_", "EMERGENCY_STOP", "HW_PAL_ARM_BASE_MOTOR_EMERGENCY_STOP"),
    (("left_arm", "wheelMotor-1"), "HW_", "ERROR_HW", "HW_LEFT_ARM_WHEEL_MOTOR_1_ERROR_HW"),
    (("arm-1", "j1"), "HW_", "SAFETY_STOP", "HW_ARM_1_J1_SAFETY_STOP"),
    # docs/bridges/node_state.md
    (("/robot1/lidar_driver",), "NODE_", "HEARTBEAT_LOST",
     "NODE_ROBOT1_LIDAR_DRIVER_HEARTBEAT_LOST"),
    (("/a//b-c.d",), "NODE_", "ERROR", "NODE_A_B_C_D_ERROR"),
])
def test_documented_short_codes(names: tuple[str, ...], prefix: str, suffix: str,
                                code: str) -> None:
    assert fault_code(*names, prefix=prefix, suffix=suffix) == code
