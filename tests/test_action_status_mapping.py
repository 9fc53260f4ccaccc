"""The action-status mapping without ROS: net state, fault codes, filters, transitions in both
judgement modes, goal outcomes, settings."""

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
    GoalOutcome,
    Judge,
    Net,
    RecordedGoals,
    Rules,
    SeenGoals,
    Transition,
    action_of_topic,
    goal_text,
    is_watched,
    net_state,
)
from faultledger.ros.bridges.codes import MAX_CODE_LENGTH, fault_code, upper_snake


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


def code(prefix: str, action: str, suffix: str) -> str:
    """The bridge's code: ``<prefix>_<ACTION>_<suffix>`` by the shared rule."""
    return fault_code(action, prefix=f"{prefix}_", suffix=suffix)


def test_short_codes_are_prefix_name_suffix() -> None:
    assert code("ACTION", "/navigate_to_pose", "ABORTED") == "ACTION_NAVIGATE_TO_POSE_ABORTED"
    assert code("NAV", "/robot1/arm/follow_joint_trajectory", "CANCELED") == \
        "NAV_ROBOT1_ARM_FOLLOW_JOINT_TRAJECTORY_CANCELED"


def test_the_tracker_reports_the_shared_codes() -> None:
    action = "/robot1/joint_trajectory_controller/follow_joint_trajectory_" + "x" * 120
    failed, = ActionTracker(Rules("NAV")).observe(action, [(gid(1), STATUS_ABORTED)])
    assert failed.code == code("NAV", action, "ABORTED")
    assert len(failed.code) == MAX_CODE_LENGTH and failed.code.endswith("_ABORTED")


def test_long_codes_are_cut_hashed_and_keep_the_suffix() -> None:
    base = "/robot1/joint_trajectory_controller/follow_joint_trajectory_with_extra_words" * 2
    one, two = base + "_left", base + "_right"
    codes = [code("ACTION", a, s) for a in (one, two) for s in ("ABORTED", "CANCELED")]
    assert len(set(codes)) == 4
    for c in codes:
        assert len(c) == MAX_CODE_LENGTH
        assert fault_code_error(c) is None
        pattern = r"ACTION_ROBOT1_JOINT_TRAJECTORY_[A-Z0-9_]*_[0-9A-F]{8}_(ABORTED|CANCELED)"
        assert re.fullmatch(pattern, c), c
    assert codes[0].endswith("_ABORTED") and codes[1].endswith("_CANCELED")
    # Deterministic: the same action always gets the same code.
    assert code("ACTION", one, "ABORTED") == codes[0]


def test_a_code_of_exactly_128_characters_is_not_hashed() -> None:
    action = "/" + "a" * (128 - len("ACTION__ABORTED"))
    c = code("ACTION", action, "ABORTED")
    assert len(c) == 128 and c == f"ACTION_{'A' * 113}_ABORTED"
    assert len(code("ACTION", action + "b", "ABORTED")) == 128
    assert code("ACTION", action + "b", "ABORTED") != c


def test_codes_up_to_128_characters_are_no_longer_hashed() -> None:
    """Up to 0.1.0 the limit was 64 (and sha1): such a name now keeps its full code."""
    action = "/robot1/joint_trajectory_controller_of_the_left_arm_of_the_robot/follow_joint"
    assert code("ACTION", action, "ABORTED") == \
        "ACTION_ROBOT1_JOINT_TRAJECTORY_CONTROLLER_OF_THE_LEFT_ARM_OF_THE_ROBOT_FOLLOW_JOINT_ABORTED"


def test_the_longest_prefix_still_fits() -> None:
    c = code("P" * 32, "/" + "x" * 200, "CANCELED")
    assert len(c) <= 128 and c.endswith("_CANCELED") and fault_code_error(c) is None


def test_a_name_without_letters_gets_the_hash() -> None:
    assert re.fullmatch(r"ACTION_[0-9A-F]{8}_ABORTED", code("ACTION", "/__", "ABORTED"))


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


MODES: tuple[Judge, ...] = ("whole_array", "new_goals")


def test_whole_array_is_the_default() -> None:
    assert Rules().judge == "whole_array"


@pytest.mark.parametrize("judge", MODES)
def test_a_retry_loop_as_a_server_publishes_it(judge: Judge) -> None:
    """rcl_action republishes finished goals: [A1], [A1 A2], [A1 A2 S3], [A1 A2 S3 A4].

    whole_array: raised once at the first abort; the success does not heal while the aborted
    goals are still in the array. new_goals: the success heals at once, the next abort raises
    again."""
    tracker = ActionTracker(Rules(judge=judge))
    arrays = [
        [(gid(1), STATUS_ACCEPTED)],
        [(gid(1), STATUS_EXECUTING)],
        [(gid(1), STATUS_ABORTED)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_EXECUTING)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_ABORTED)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_ABORTED), (gid(3), STATUS_EXECUTING)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_ABORTED), (gid(3), STATUS_SUCCEEDED)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_ABORTED), (gid(3), STATUS_SUCCEEDED)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_ABORTED), (gid(3), STATUS_SUCCEEDED),
         (gid(4), STATUS_ABORTED)],
    ]
    out = [codes(tracker.observe(A, array)) for array in arrays]
    raised, healed = [(ABORTED_CODE, False)], [(ABORTED_CODE, True)]
    if judge == "whole_array":
        assert out == [[], [], raised, [], [], [], [], [], []]
    else:
        assert out == [[], [], raised, [], [], [], healed, [], raised]


def test_whole_array_heals_once_the_aborted_goals_leave_the_array() -> None:
    """The server forgets finished goals after its result_timeout."""
    tracker = ActionTracker(Rules())
    assert codes(tracker.observe(A, [(gid(1), STATUS_ABORTED)])) == [(ABORTED_CODE, False)]
    assert tracker.observe(A, [(gid(1), STATUS_ABORTED), (gid(2), STATUS_SUCCEEDED)]) == []
    assert tracker.failed(A)
    assert codes(tracker.observe(A, [(gid(2), STATUS_SUCCEEDED)])) == [(ABORTED_CODE, True)]
    assert tracker.observe(A, [(gid(2), STATUS_SUCCEEDED)]) == []
    # Everything forgotten: an empty array changes nothing.
    assert tracker.observe(A, []) == [] and not tracker.failed(A)
    # A new abort while healthy is a new edge, even with the old success still remembered.
    assert codes(tracker.observe(A, [(gid(2), STATUS_SUCCEEDED), (gid(3), STATUS_ABORTED)])) \
        == [(ABORTED_CODE, False)]


def test_whole_array_an_empty_array_keeps_a_failed_action_failed() -> None:
    tracker = ActionTracker(Rules())
    tracker.observe(A, [(gid(1), STATUS_ABORTED)])
    assert tracker.observe(A, []) == [] and tracker.failed(A)


@pytest.mark.parametrize("judge", MODES)
def test_a_restarted_bridge_raises_again_for_aborted_goals_still_remembered(
        judge: Judge) -> None:
    """A new tracker starts healthy: the first array it gets (the server's latest, latched)
    counts in full in both modes."""
    array = [(gid(1), STATUS_ABORTED), (gid(2), STATUS_SUCCEEDED)]
    before = ActionTracker(Rules(judge=judge))
    before.observe(A, array[:1])
    before.observe(A, array)
    after = ActionTracker(Rules(judge=judge))
    assert codes(after.observe(A, array)) == [(ABORTED_CODE, False)]


def test_new_goals_a_republished_array_judges_nothing() -> None:
    tracker = ActionTracker(Rules(judge="new_goals"))
    array = [(gid(1), STATUS_ABORTED)]
    assert codes(tracker.observe(A, array)) == [(ABORTED_CODE, False)]
    assert codes(tracker.observe(A, [(gid(1), STATUS_ABORTED), (gid(2), STATUS_SUCCEEDED)])) \
        == [(ABORTED_CODE, True)]
    # The same array again: nothing new, nothing judged (whole_array would find it failed).
    assert tracker.observe(A, [(gid(1), STATUS_ABORTED), (gid(2), STATUS_SUCCEEDED)]) == []
    whole = ActionTracker(Rules())
    whole.observe(A, [(gid(2), STATUS_SUCCEEDED)])
    assert codes(whole.observe(A, [(gid(1), STATUS_ABORTED), (gid(2), STATUS_SUCCEEDED)])) \
        == [(ABORTED_CODE, False)]


@pytest.mark.parametrize("judge", MODES)
def test_two_new_goals_in_one_array_one_aborted_is_failed(judge: Judge) -> None:
    tracker = ActionTracker(Rules(judge=judge))
    out = tracker.observe(A, [(gid(2), STATUS_SUCCEEDED), (gid(1), STATUS_ABORTED)])
    assert codes(out) == [(ABORTED_CODE, False)]


@pytest.mark.parametrize("judge", MODES)
def test_non_terminal_empty_and_invalid_arrays_change_nothing(judge: Judge) -> None:
    tracker = ActionTracker(Rules(judge=judge))
    assert tracker.observe(A, [(gid(1), STATUS_ABORTED)]) != []
    for array in ([], [(gid(2), 42)], [(gid(3), STATUS_EXECUTING)], [(gid(4), STATUS_UNKNOWN)]):
        assert tracker.observe(A, array) == []
        assert tracker.failed(A)


@pytest.mark.parametrize("judge", MODES)
def test_canceled_is_healthy_unless_it_is_a_fault(judge: Judge) -> None:
    tracker = ActionTracker(Rules(judge=judge))
    tracker.observe(A, [(gid(1), STATUS_ABORTED)])
    assert codes(tracker.observe(A, [(gid(2), STATUS_CANCELED)])) == [(ABORTED_CODE, True)]
    strict = ActionTracker(Rules(canceled_is_fault=True, severity=3, judge=judge))
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


# -- goal outcomes ---------------------------------------------------------------------------------
def test_each_goal_is_recorded_once_across_republished_arrays() -> None:
    recorded = RecordedGoals(100)
    arrays = [
        [(gid(1), STATUS_EXECUTING)],
        [(gid(1), STATUS_ABORTED)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_ACCEPTED)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_SUCCEEDED), (gid(3), STATUS_CANCELED),
         (gid(4), 42), (gid(5), STATUS_CANCELING)],
        [(gid(1), STATUS_ABORTED), (gid(2), STATUS_SUCCEEDED), (gid(3), STATUS_CANCELED)],
    ]
    out = [recorded.new_outcomes(A, array, received_ns=100 + i) for i, array in enumerate(arrays)]
    assert out == [
        [],
        [GoalOutcome(A, goal_text(gid(1)), "ABORTED", 101)],  # when the end was first seen
        [],
        [GoalOutcome(A, goal_text(gid(2)), "SUCCEEDED", 103),
         GoalOutcome(A, goal_text(gid(3)), "CANCELED", 103)],
        [],
    ]
    # Outcomes are per action: the same goal id on another action is another goal.
    assert [o.action for o in recorded.new_outcomes("/other", arrays[1], 7)] == ["/other"]
    assert len(recorded) == 4


def test_recorded_goals_is_a_bounded_lru() -> None:
    recorded = RecordedGoals(2)
    assert len(recorded.new_outcomes(A, [(gid(1), STATUS_ABORTED)], 0)) == 1
    assert len(recorded.new_outcomes(A, [(gid(2), STATUS_ABORTED)], 0)) == 1
    assert recorded.new_outcomes(A, [(gid(1), STATUS_ABORTED)], 0) == []  # refreshed
    assert len(recorded.new_outcomes(A, [(gid(3), STATUS_ABORTED)], 0)) == 1  # evicts 2
    # Forgotten: sent again (the manager stores a goal's outcome once anyway).
    assert len(recorded.new_outcomes(A, [(gid(2), STATUS_ABORTED)], 0)) == 1
    assert RecordedGoals(0).capacity == 1


def test_settings_defaults_are_the_documented_ones() -> None:
    pytest.importorskip("rclpy")
    from faultledger.ros.bridges.action_status import Settings

    assert Settings().model_dump() == {
        "rescan_period_sec": 2.0, "code_prefix": "ACTION", "aborted_severity": 2,
        "canceled_is_fault": False, "heal_on_succeeded": True, "judge": "whole_array",
        "exclude_actions": [], "include_only_actions": [], "dedup_capacity": 4096,
    }
    from faultledger.ros.bridges.settings import normalise

    warnings: list[str] = []
    settings = normalise(Settings, {"code_prefix": "NAV", "aborted_severity": 7,
                                    "rescan_period_sec": 0.5, "judge": "newest"},
                         warnings.append)
    assert (settings.code_prefix, settings.aborted_severity, settings.rescan_period_sec,
            settings.judge) == ("NAV", 2, 0.5, "whole_array")
    assert len(warnings) == 2
    assert normalise(Settings, {"judge": "new_goals"}, warnings.append).judge == "new_goals"


@pytest.mark.parametrize("prefix, converted", [
    ("acc-d", "ACC_D"),
    ("Nav Stack", "NAV_STACK"),
    ("navStack", "NAV_STACK"),
    ("nav", "NAV"),
    ("NAV..X", "NAV_X"),
    ("_R2_", "R2"),
])
def test_a_code_prefix_not_in_upper_snake_case_is_converted_with_a_warning(
        prefix: str, converted: str) -> None:
    pytest.importorskip("rclpy")
    from faultledger.ros.bridges.action_status import Settings
    from faultledger.ros.bridges.settings import normalise

    warnings: list[str] = []
    settings = normalise(Settings, {"code_prefix": prefix}, warnings.append, "action_status")
    assert settings.code_prefix == converted
    assert warnings == [f"action_status.code_prefix={prefix!r} is not upper snake case; "
                        f"using {converted!r}"]


@pytest.mark.parametrize("prefix", ["ACTION", "NAV_STACK", "R2", "A" * 32])
def test_an_upper_snake_code_prefix_is_kept_silently(prefix: str) -> None:
    pytest.importorskip("rclpy")
    from faultledger.ros.bridges.action_status import Settings
    from faultledger.ros.bridges.settings import normalise

    warnings: list[str] = []
    assert normalise(Settings, {"code_prefix": prefix}, warnings.append).code_prefix == prefix
    assert warnings == []


@pytest.mark.parametrize("prefix", ["---", "", "A" * 33, 42])
def test_a_code_prefix_without_a_usable_conversion_falls_back_to_the_default(
        prefix: object) -> None:
    pytest.importorskip("rclpy")
    from faultledger.ros.bridges.action_status import Settings
    from faultledger.ros.bridges.settings import normalise

    warnings: list[str] = []
    assert normalise(Settings, {"code_prefix": prefix}, warnings.append).code_prefix == "ACTION"
    assert warnings and warnings[-1].startswith(f"code_prefix={prefix!r} is invalid")


def test_the_shipped_config_holds_exactly_the_defaults() -> None:
    pytest.importorskip("rclpy")
    from faultledger.ros.bridges.action_status import Settings
    from faultledger.ros.bridges.settings import read_yaml

    path = Path(__file__).parents[1] / "config" / "action_status.yaml"
    raw = read_yaml(path)
    assert set(raw) == set(Settings.model_fields)
    assert Settings.model_validate(raw) == Settings()
