"""The action-status mapping without ROS: net state, fault codes, filters, transitions."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from faultledger.domain.validation import fault_code_error
from faultledger.ros.bridges.action_status_mapping import (
    STATUS_ABORTED,
    STATUS_ACCEPTED,
    STATUS_CANCELED,
    STATUS_CANCELING,
    STATUS_EXECUTING,
    STATUS_SUCCEEDED,
    STATUS_UNKNOWN,
    ActionTracker,
    Net,
    Rules,
    SeenGoals,
    Transition,
    action_of_topic,
    fault_code,
    goal_text,
    is_watched,
    net_state,
    upper_snake,
)


def gid(n: int) -> bytes:
    return bytes([n]) * 16


# -- net state -------------------------------------------------------------------------------------
@pytest.mark.parametrize("statuses, canceled_is_fault, net", [
    ([], False, Net.UNCHANGED),
    ([STATUS_ACCEPTED, STATUS_EXECUTING, STATUS_CANCELING, STATUS_UNKNOWN], False, Net.UNCHANGED),
    ([42, -1], False, Net.UNCHANGED),
    ([STATUS_SUCCEEDED], False, Net.HEALTHY),
    ([STATUS_CANCELED], False, Net.HEALTHY),
    ([STATUS_CANCELED], True, Net.FAILED),
    ([STATUS_ABORTED], False, Net.FAILED),
    ([STATUS_ABORTED, STATUS_SUCCEEDED], False, Net.FAILED),
    ([STATUS_SUCCEEDED, STATUS_ABORTED], False, Net.FAILED),
    ([STATUS_SUCCEEDED, STATUS_CANCELED, STATUS_EXECUTING], True, Net.FAILED),
    ([STATUS_EXECUTING, STATUS_SUCCEEDED, 42], False, Net.HEALTHY),
])
def test_net_state_any_failure_wins_regardless_of_order(
        statuses: list[int], canceled_is_fault: bool, net: Net) -> None:
    goals = [(gid(i), s) for i, s in enumerate(statuses)]
    assert net_state(goals, canceled_is_fault).net is net


def test_net_state_names_the_failing_goals_per_kind() -> None:
    goals = [(gid(1), STATUS_ABORTED), (gid(2), STATUS_CANCELED), (gid(3), STATUS_ABORTED)]
    verdict = net_state(goals, canceled_is_fault=True)
    assert verdict.failing == {"ABORTED": [goals[0], goals[2]], "CANCELED": [goals[1]]}


# -- codes -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("action, snake", [
    ("/navigate_to_pose", "NAVIGATE_TO_POSE"),
    ("/robot1/arm/follow_joint_trajectory", "ROBOT1_ARM_FOLLOW_JOINT_TRAJECTORY"),
    ("/joint_trajectory_controller/follow_joint_trajectory",
     "JOINT_TRAJECTORY_CONTROLLER_FOLLOW_JOINT_TRAJECTORY"),
    ("/robot/moveGroup", "ROBOT_MOVE_GROUP"),
    ("/a__b/_c", "A_B_C"),
])
def test_action_names_become_upper_snake(action: str, snake: str) -> None:
    assert upper_snake(action) == snake


def test_short_codes_are_prefix_name_suffix() -> None:
    assert fault_code("ACTION", "/navigate_to_pose", "ABORTED") == "ACTION_NAVIGATE_TO_POSE_ABORTED"
    assert fault_code("NAV", "/robot1/arm/follow_joint_trajectory", "CANCELED") == \
        "NAV_ROBOT1_ARM_FOLLOW_JOINT_TRAJECTORY_CANCELED"


def test_long_codes_are_cut_hashed_and_keep_the_suffix() -> None:
    base = "/robot1/joint_trajectory_controller/follow_joint_trajectory_with_extra_words"
    one, two = base + "_left", base + "_right"
    codes = [fault_code("ACTION", a, s) for a in (one, two) for s in ("ABORTED", "CANCELED")]
    assert len(set(codes)) == 4
    for code in codes:
        assert len(code) <= 64
        assert fault_code_error(code) is None
        pattern = r"ACTION_ROBOT1_JOINT_TRAJECTORY_[A-Z_]*_[0-9A-F]{6}_(ABORTED|CANCELED)"
        assert re.fullmatch(pattern, code), code
    assert codes[0].endswith("_ABORTED") and codes[1].endswith("_CANCELED")
    # Deterministic: the same action always gets the same code.
    assert fault_code("ACTION", one, "ABORTED") == codes[0]


def test_a_code_of_exactly_64_characters_is_not_hashed() -> None:
    action = "/" + "a" * (64 - len("ACTION__ABORTED"))
    code = fault_code("ACTION", action, "ABORTED")
    assert len(code) == 64 and code == f"ACTION_{'A' * 49}_ABORTED"
    assert len(fault_code("ACTION", action + "b", "ABORTED")) == 64


def test_the_longest_prefix_still_fits() -> None:
    code = fault_code("P" * 32, "/" + "x" * 200, "CANCELED")
    assert len(code) <= 64 and code.endswith("_CANCELED") and fault_code_error(code) is None


def test_a_name_without_letters_gets_the_hash() -> None:
    assert re.fullmatch(r"ACTION_[0-9A-F]{6}_ABORTED", fault_code("ACTION", "/__", "ABORTED"))


def test_status_topics_name_their_action() -> None:
    assert action_of_topic("/robot1/navigate_to_pose/_action/status") == "/robot1/navigate_to_pose"
    assert action_of_topic("/navigate_to_pose/_action/feedback") is None
    assert action_of_topic("/_action/status") is None
    assert goal_text(bytes(range(16))) == "00010203-0405-0607-0809-0a0b0c0d0e0f"
    assert goal_text(b"\x01\x02") == "0102"


# -- filters ---------------------------------------------------------------------------------------
def test_filters_are_unanchored_substrings_and_exclude_wins() -> None:
    assert is_watched("/navigate_to_pose", [], [])
    assert not is_watched("/robot1/navigate_to_pose", ["navigate"], [])
    assert is_watched("/robot1/spin", ["navigate"], [])
    assert is_watched("/robot1/spin", [], ["robot1", "robot2"])
    assert not is_watched("/robot3/spin", [], ["robot1", "robot2"])
    assert not is_watched("/robot1/spin", ["spin"], ["robot1"])


# -- transitions -----------------------------------------------------------------------------------
A = "/navigate_to_pose"
ABORTED_CODE = "ACTION_NAVIGATE_TO_POSE_ABORTED"
CANCELED_CODE = "ACTION_NAVIGATE_TO_POSE_CANCELED"


def codes(transitions: list[Transition]) -> list[tuple[str, bool]]:
    return [(t.code, t.passed) for t in transitions]


def test_raise_on_healthy_to_failed_and_heal_on_failed_to_healthy() -> None:
    tracker = ActionTracker(Rules())
    assert tracker.observe(A, [(gid(1), STATUS_SUCCEEDED)]) == []  # starts healthy
    [failed] = tracker.observe(A, [(gid(1), STATUS_SUCCEEDED), (gid(2), STATUS_ABORTED)])
    assert (failed.code, failed.passed, failed.severity) == (ABORTED_CODE, False, 2)
    assert failed.description == f"action {A}: goal {goal_text(gid(2))} ABORTED"
    assert tracker.failed(A)
    assert codes(tracker.observe(A, [(gid(3), STATUS_SUCCEEDED)])) == [(ABORTED_CODE, True)]
    assert not tracker.failed(A)


def test_a_retry_loop_as_a_server_publishes_it_raises_once_and_heals_once() -> None:
    """rcl_action republishes finished goals: [A1], [A1 A2], [A1 A2 S3]."""
    tracker = ActionTracker(Rules())
    arrays = [
        [(gid(1), STATUS_ACCEPTED)],
        [(gid(1), STATUS_EXECUTING)],
        [(gid(1), STATUS_ABORTED)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_EXECUTING)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_ABORTED)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_ABORTED), (gid(3), STATUS_EXECUTING)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_ABORTED), (gid(3), STATUS_SUCCEEDED)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_ABORTED), (gid(3), STATUS_SUCCEEDED)],
    ]
    out = [codes(tracker.observe(A, array)) for array in arrays]
    assert out == [[], [], [(ABORTED_CODE, False)], [], [], [], [(ABORTED_CODE, True)], []]


def test_two_new_goals_in_one_array_one_aborted_is_failed() -> None:
    tracker = ActionTracker(Rules())
    out = tracker.observe(A, [(gid(2), STATUS_SUCCEEDED), (gid(1), STATUS_ABORTED)])
    assert codes(out) == [(ABORTED_CODE, False)]


def test_non_terminal_empty_and_invalid_arrays_change_nothing() -> None:
    tracker = ActionTracker(Rules())
    assert tracker.observe(A, [(gid(1), STATUS_ABORTED)]) != []
    for array in ([], [(gid(2), 42)], [(gid(3), STATUS_EXECUTING)], [(gid(4), STATUS_UNKNOWN)]):
        assert tracker.observe(A, array) == []
        assert tracker.failed(A)


def test_canceled_is_healthy_unless_it_is_a_fault() -> None:
    tracker = ActionTracker(Rules())
    tracker.observe(A, [(gid(1), STATUS_ABORTED)])
    assert codes(tracker.observe(A, [(gid(2), STATUS_CANCELED)])) == [(ABORTED_CODE, True)]
    strict = ActionTracker(Rules(canceled_is_fault=True, severity=3))
    [failed] = strict.observe(A, [(gid(1), STATUS_CANCELED)])
    assert (failed.code, failed.severity) == (CANCELED_CODE, 3)
    # A new kind of failure while failed is its own edge; healing heals both.
    assert codes(strict.observe(A, [(gid(2), STATUS_ABORTED)])) == [(ABORTED_CODE, False)]
    assert codes(strict.observe(A, [(gid(3), STATUS_ABORTED)])) == []
    assert codes(strict.observe(A, [(gid(4), STATUS_SUCCEEDED)])) == \
        [(CANCELED_CODE, True), (ABORTED_CODE, True)]


def test_without_healing_no_passed_but_the_next_failure_raises_again() -> None:
    tracker = ActionTracker(Rules(heal_on_succeeded=False))
    assert codes(tracker.observe(A, [(gid(1), STATUS_ABORTED)])) == [(ABORTED_CODE, False)]
    assert tracker.observe(A, [(gid(2), STATUS_SUCCEEDED)]) == []
    assert codes(tracker.observe(A, [(gid(3), STATUS_ABORTED)])) == [(ABORTED_CODE, False)]
    assert tracker.drop(A) == []


def test_a_vanished_failed_action_is_healed_and_forgotten() -> None:
    tracker = ActionTracker(Rules())
    tracker.observe(A, [(gid(1), STATUS_ABORTED)])
    tracker.observe("/other", [(gid(1), STATUS_SUCCEEDED)])
    assert codes(tracker.drop(A)) == [(ABORTED_CODE, True)]
    assert tracker.drop("/other") == [] and tracker.drop("/never") == []
    # Seen again: a fresh start, the same old goal counts as new.
    assert codes(tracker.observe(A, [(gid(1), STATUS_ABORTED)])) == [(ABORTED_CODE, False)]


def test_description_names_at_most_five_goals() -> None:
    tracker = ActionTracker(Rules())
    [failed] = tracker.observe(A, [(gid(i), STATUS_ABORTED) for i in range(7)])
    assert failed.description.startswith(f"action {A}: goals {goal_text(gid(0))}, ")
    assert failed.description.endswith(" and 2 more ABORTED")


def test_seen_goals_is_a_bounded_lru() -> None:
    seen = SeenGoals(2)
    assert seen.first_time(A, gid(1), STATUS_ABORTED)
    assert not seen.first_time(A, gid(1), STATUS_ABORTED)
    assert seen.first_time(A, gid(1), STATUS_SUCCEEDED)
    assert not seen.first_time(A, gid(1), STATUS_ABORTED)  # refreshed: now the newest
    assert seen.first_time(A, gid(2), STATUS_ABORTED)  # evicts (1, SUCCEEDED)
    assert len(seen) == 2
    assert seen.first_time(A, gid(1), STATUS_SUCCEEDED)
    assert SeenGoals(0).capacity == 1


def test_settings_defaults_are_the_documented_ones() -> None:
    pytest.importorskip("rclpy")
    from faultledger.ros.bridges.action_status import Settings

    assert Settings().model_dump() == {
        "rescan_period_sec": 2.0, "code_prefix": "ACTION", "aborted_severity": 2,
        "canceled_is_fault": False, "heal_on_succeeded": True, "exclude_actions": [],
        "include_only_actions": [], "dedup_capacity": 4096,
    }
    from faultledger.ros.bridges.settings import normalise

    warnings: list[str] = []
    settings = normalise(Settings, {"code_prefix": "NAV..X", "aborted_severity": 7,
                                    "rescan_period_sec": 0.5}, warnings.append)
    assert (settings.code_prefix, settings.aborted_severity, settings.rescan_period_sec) == \
        ("ACTION", 2, 0.5)
    assert len(warnings) == 2


def test_the_shipped_config_holds_exactly_the_defaults() -> None:
    pytest.importorskip("rclpy")
    from faultledger.ros.bridges.action_status import Settings
    from faultledger.ros.bridges.settings import read_yaml

    path = Path(__file__).parents[1] / "config" / "action_status.yaml"
    raw = read_yaml(path)
    assert set(raw) == set(Settings.model_fields)
    assert Settings.model_validate(raw) == Settings()
