"""SPEC §4.1-4.3: policy sanitising, per-source overrides, debounce state machine, field rules."""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime, timedelta, timezone
from typing import Any

import pytest

from faultledger import ClearResult, Fault, FaultLedger, FaultStatus, Policy, ReportResult

OpenLedger = Callable[..., FaultLedger]

T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)
CODE = "MOTOR_OVERHEAT"

PF = FaultStatus.PREFAILED
PP = FaultStatus.PREPASSED
C = FaultStatus.CONFIRMED
H = FaultStatus.HEALED
CL = FaultStatus.CLEARED


def at(seconds: float) -> datetime:
    return T0 + timedelta(seconds=seconds)


def failed(
    ledger: FaultLedger,
    when: datetime,
    *,
    severity: int = 1,
    source: str = "/motor",
    description: str = "",
    code: str = CODE,
) -> ReportResult:
    result = ledger.report(
        code, "FAILED", severity=severity, description=description, source_id=source, at=when
    )
    assert result.accepted, result.message
    return result


def passed(
    ledger: FaultLedger,
    when: datetime,
    *,
    severity: int = 0,
    source: str = "/motor",
    description: str = "",
    code: str = CODE,
) -> ReportResult:
    result = ledger.report(
        code, "PASSED", severity=severity, description=description, source_id=source, at=when
    )
    assert result.accepted, result.message
    return result


def clear(ledger: FaultLedger, code: str = CODE) -> ClearResult:
    result = ledger.clear(code, actor="test:operator", reason="")
    assert result.success, result.message
    return result


FAULT_FIELDS = (
    "fault_code", "severity", "description", "first_occurred", "last_occurred", "last_passed",
    "occurrence_count", "status", "reporting_sources", "debounce_counter",
)


def fields_of(f: Fault) -> dict[str, object]:
    return {name: getattr(f, name) for name in FAULT_FIELDS}


def fault(ledger: FaultLedger, code: str = CODE) -> Fault:
    found = ledger.get_fault(code)
    assert found is not None, f"{code} should exist"
    return found


# Steps of a script: F = FAILED (WARN), F! = FAILED (CRITICAL), P = PASSED, P! = PASSED with
# severity CRITICAL, C = operator clear.
def apply_step(ledger: FaultLedger, step: str, when: datetime, *, source: str = "/motor") -> None:
    if step == "F":
        failed(ledger, when, severity=1, source=source)
    elif step == "F!":
        failed(ledger, when, severity=3, source=source)
    elif step == "P":
        passed(ledger, when, severity=0, source=source)
    elif step == "P!":
        passed(ledger, when, severity=3, source=source)
    elif step == "C":
        clear(ledger)
    else:
        raise AssertionError(f"unknown step {step!r}")


def trajectory(
    ledger: FaultLedger, steps: list[str], *, source: str = "/motor"
) -> list[tuple[FaultStatus, int]]:
    """(status, debounce_counter) after each step."""
    seen: list[tuple[FaultStatus, int]] = []
    for i, step in enumerate(steps):
        apply_step(ledger, step, at(i), source=source)
        f = fault(ledger)
        seen.append((f.status, f.debounce_counter))
    return seen


# --------------------------------------------------------------------------------------------
# §4.1 policy: defaults and sanitising
# --------------------------------------------------------------------------------------------


def test_policy_defaults() -> None:
    policy = Policy()
    assert (
        policy.confirmation_threshold,
        policy.healing_enabled,
        policy.healing_threshold,
        policy.auto_confirm_after_sec,
    ) == (-1, False, 3, 0)


@pytest.mark.parametrize(
    ("given", "sanitised"),
    [
        pytest.param(5, -5, id="positive_is_negated"),
        pytest.param(1, -1, id="plus_one_is_negated"),
        pytest.param(0, -1, id="zero_becomes_minus_one"),
        pytest.param(-3, -3, id="negative_kept"),
    ],
)
def test_policy_sanitises_confirmation_threshold(given: int, sanitised: int) -> None:
    assert Policy(confirmation_threshold=given).confirmation_threshold == sanitised


@pytest.mark.parametrize(
    ("given", "sanitised"),
    [
        pytest.param(-2, 2, id="negative_is_negated"),
        pytest.param(0, 0, id="zero_allowed"),
        pytest.param(4, 4, id="positive_kept"),
    ],
)
def test_policy_sanitises_healing_threshold(given: int, sanitised: int) -> None:
    assert Policy(healing_threshold=given).healing_threshold == sanitised


# --------------------------------------------------------------------------------------------
# §4.2 debounce state machine, as (status, counter) trajectories
# --------------------------------------------------------------------------------------------

DEBOUNCE_3_HEAL_3 = {"confirmation_threshold": -3, "healing_enabled": True, "healing_threshold": 3}

TRAJECTORIES = [
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "F", "F"],
        [(PF, -1), (PF, -2), (C, -3)],
        id="failed_reports_count_down_to_confirmation",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "F", "F", "F", "F"],
        [(PF, -1), (PF, -2), (C, -3), (C, -3), (C, -3)],
        id="counter_clamped_at_confirmation_threshold",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "F", "F", "F", "F", "P"],
        [(PF, -1), (PF, -2), (C, -3), (C, -3), (C, -3), (C, -2)],
        id="passed_after_clamp_moves_one_step_from_threshold",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "F", "F", "P", "P", "P", "P", "P", "P"],
        [(PF, -1), (PF, -2), (C, -3), (C, -2), (C, -1), (C, 0), (C, 1), (C, 2), (H, 3)],
        id="confirmed_latches_until_healing_threshold",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "F", "F", "P", "P", "P", "P", "P", "P", "P", "P"],
        [(PF, -1), (PF, -2), (C, -3), (C, -2), (C, -1), (C, 0), (C, 1), (C, 2), (H, 3),
         (H, 3), (H, 3)],
        id="counter_clamped_at_healing_threshold",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "F", "F", "P", "P", "P", "P", "P", "P", "F", "F", "F", "F", "F", "F"],
        [(PF, -1), (PF, -2), (C, -3), (C, -2), (C, -1), (C, 0), (C, 1), (C, 2), (H, 3),
         (H, 2), (H, 1), (H, 0), (H, -1), (H, -2), (C, -3)],
        id="healed_latches_until_confirmation_threshold",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "P"],
        [(PF, -1), (PF, 0)],
        id="zero_counter_keeps_prefailed",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "P", "P", "F"],
        [(PF, -1), (PF, 0), (PP, 1), (PP, 0)],
        id="zero_counter_keeps_prepassed",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "P", "P", "P", "F", "F", "F"],
        [(PF, -1), (PF, 0), (PP, 1), (PP, 2), (PP, 1), (PP, 0), (PF, -1)],
        id="positive_counter_is_prepassed_negative_is_prefailed",
    ),
    pytest.param(
        {"confirmation_threshold": -1, "healing_enabled": False, "healing_threshold": 3},
        ["F", "P", "P", "P", "P", "P"],
        [(C, -1), (C, 0), (C, 1), (C, 2), (C, 3), (C, 3)],
        id="healing_disabled_never_heals_and_counter_still_clamped",
    ),
    pytest.param(
        {"confirmation_threshold": -1, "healing_enabled": True, "healing_threshold": 0},
        ["F", "P"],
        [(C, -1), (H, 0)],
        id="healing_threshold_zero_heals_at_zero",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F!"],
        [(C, -1)],
        id="critical_failed_confirms_new_fault_at_once",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "F!"],
        [(PF, -1), (C, -2)],
        id="critical_failed_confirms_prefailed_fault",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "P", "P", "F!"],
        [(PF, -1), (PF, 0), (PP, 1), (C, 0)],
        id="critical_failed_confirms_prepassed_fault",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "F", "F", "P", "P", "P", "P", "P", "P", "F!"],
        [(PF, -1), (PF, -2), (C, -3), (C, -2), (C, -1), (C, 0), (C, 1), (C, 2), (H, 3),
         (C, 2)],
        id="critical_failed_confirms_healed_fault",
    ),
    pytest.param(
        DEBOUNCE_3_HEAL_3,
        ["F", "P!"],
        [(PF, -1), (PF, 0)],
        id="critical_passed_does_not_confirm",
    ),
    pytest.param(
        {},
        ["F", "P", "P", "P", "P"],
        [(C, -1), (C, 0), (C, 1), (C, 2), (C, 3)],
        id="default_policy_confirms_on_first_failed_and_never_heals",
    ),
    pytest.param(
        {"confirmation_threshold": 3},
        ["F", "F", "F"],
        [(PF, -1), (PF, -2), (C, -3)],
        id="sanitised_positive_confirmation_threshold_is_used",
    ),
    pytest.param(
        {"confirmation_threshold": 0},
        ["F"],
        [(C, -1)],
        id="sanitised_zero_confirmation_threshold_is_used",
    ),
    pytest.param(
        {"confirmation_threshold": -1, "healing_enabled": True, "healing_threshold": -2},
        ["F", "P", "P", "P"],
        [(C, -1), (C, 0), (C, 1), (H, 2)],
        id="sanitised_negative_healing_threshold_is_used",
    ),
]


@pytest.mark.parametrize(("policy", "steps", "expected"), TRAJECTORIES)
def test_debounce_trajectory(
    open_ledger: OpenLedger,
    policy: dict[str, Any],
    steps: list[str],
    expected: list[tuple[FaultStatus, int]],
) -> None:
    ledger = open_ledger(Policy(**policy))
    assert trajectory(ledger, steps) == expected


@pytest.mark.parametrize(
    ("event_types", "expected"),
    [
        pytest.param((0, 1), [(PF, -1), (PF, 0)], id="wire_values"),
        pytest.param(("FAILED", "PASSED"), [(PF, -1), (PF, 0)], id="names"),
    ],
)
def test_event_type_accepts_name_or_wire_value(
    open_ledger: OpenLedger,
    event_types: tuple[str | int, ...],
    expected: list[tuple[FaultStatus, int]],
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    seen: list[tuple[FaultStatus, int]] = []
    for i, event_type in enumerate(event_types):
        r = ledger.report(CODE, event_type, severity=1, description="", source_id="/m", at=at(i))
        assert r.accepted, r.message
        seen.append((fault(ledger).status, fault(ledger).debounce_counter))
    assert seen == expected


def test_passed_for_unknown_fault_is_logged_and_creates_no_fault(open_ledger: OpenLedger
                                                                  ) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    log_length = len(ledger.history())

    result = ledger.report(CODE, "PASSED", severity=0, description="", source_id="/m", at=T0)

    assert result.accepted is True
    assert ledger.get_fault(CODE) is None
    [record] = ledger.history()[log_length:]
    assert (record.seq, record.kind, record.fault_code, record.payload["event_type"]) == (
        result.seq, "fault_reported", CODE, "PASSED")
    assert ledger.transitions(CODE) == []


def test_passed_for_unknown_fault_answers_with_its_seq(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    result = ledger.report(CODE, "PASSED", severity=0, description="", source_id="/m", at=T0)
    assert result.seq == ledger.last_seq
    assert "changes no fault (no such fault)" in result.message


def test_first_failed_creates_fault(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    failed(ledger, T0, severity=2, source="/motor", description="winding hot")

    f = fault(ledger)
    assert (
        f.fault_code,
        f.status,
        f.debounce_counter,
        f.severity,
        f.description,
        f.occurrence_count,
        f.first_occurred,
        f.last_occurred,
        f.last_passed,
        f.reporting_sources,
    ) == (CODE, PF, -1, 2, "winding hot", 1, T0, T0, None, ("/motor",))


def test_passed_on_cleared_fault_changes_nothing(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1, healing_enabled=True))
    failed(ledger, at(0))
    clear(ledger)
    before = fields_of(fault(ledger))

    passed(ledger, at(10), source="/other", description="looks fine", severity=3)

    assert fields_of(fault(ledger)) == before


@pytest.mark.parametrize(
    ("policy", "severity", "status"),
    [
        pytest.param({"confirmation_threshold": -3}, 1, PF, id="below_threshold_is_prefailed"),
        pytest.param({"confirmation_threshold": -1}, 1, C, id="threshold_one_is_confirmed"),
        pytest.param({"confirmation_threshold": -3}, 3, C, id="critical_is_confirmed"),
    ],
)
def test_reactivation_status_is_as_for_new_fault(
    open_ledger: OpenLedger, policy: dict[str, Any], severity: int, status: FaultStatus
) -> None:
    ledger = open_ledger(Policy(**policy))
    for i in range(3):
        failed(ledger, at(i))
    clear(ledger)

    failed(ledger, at(100), severity=severity)

    assert fault(ledger).status == status


def test_reactivation_restarts_counter_at_minus_one(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    for i in range(5):
        failed(ledger, at(i))
    clear(ledger)

    failed(ledger, at(100))

    assert fault(ledger).debounce_counter == -1


# --------------------------------------------------------------------------------------------
# §4.1 per-source overrides
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("source", "status_after_one_failed"),
    [
        pytest.param("/sensors/lidar", C, id="exact_source_matches"),
        pytest.param("/sensors/lidar/front", C, id="child_path_matches"),
        pytest.param("/sensors/lidar/front/left", C, id="grandchild_path_matches"),
        pytest.param("/sensors/lidar_rear", PF, id="longer_name_does_not_match"),
        pytest.param("/sensors/lidar2", PF, id="suffix_digit_does_not_match"),
        pytest.param("/sensors", PF, id="parent_path_does_not_match"),
        pytest.param("/robot/sensors/lidar", PF, id="prefix_must_start_the_source"),
    ],
)
def test_override_prefix_matches_only_on_path_boundary(
    open_ledger: OpenLedger, source: str, status_after_one_failed: FaultStatus
) -> None:
    ledger = open_ledger(
        Policy(
            confirmation_threshold=-3,
            overrides={"/sensors/lidar": {"confirmation_threshold": -1}},
        )
    )
    failed(ledger, T0, source=source)
    assert fault(ledger).status == status_after_one_failed


def test_override_lid_does_not_match_lidar(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(
        Policy(
            confirmation_threshold=-3,
            overrides={"/sensors/lid": {"confirmation_threshold": -1}},
        )
    )
    failed(ledger, T0, source="/sensors/lidar")
    assert fault(ledger).status == PF


NESTED_OVERRIDES = {
    "/sensors": {"confirmation_threshold": -1},
    "/sensors/lidar": {"confirmation_threshold": -2},
}


@pytest.mark.parametrize(
    "overrides",
    [
        pytest.param(NESTED_OVERRIDES, id="short_prefix_listed_first"),
        pytest.param(dict(reversed(list(NESTED_OVERRIDES.items()))), id="long_prefix_listed_first"),
    ],
)
@pytest.mark.parametrize(
    ("source", "failed_needed"),
    [
        pytest.param("/sensors/lidar/front", 2, id="lidar_child_uses_longest_prefix"),
        pytest.param("/sensors/lidar", 2, id="lidar_uses_longest_prefix"),
        pytest.param("/sensors/imu", 1, id="imu_uses_sensors_prefix"),
        pytest.param("/sensors", 1, id="sensors_exact"),
        pytest.param("/sensorsX", 5, id="no_boundary_uses_global"),
        pytest.param("/motor", 5, id="unrelated_uses_global"),
    ],
)
def test_longest_matching_override_prefix_wins(
    open_ledger: OpenLedger, overrides: dict[str, dict[str, int]], source: str, failed_needed: int
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-5, overrides=overrides))
    for i in range(failed_needed - 1):
        failed(ledger, at(i), source=source)
        assert fault(ledger).status == PF, f"confirmed too early, after {i + 1} FAILED"

    failed(ledger, at(failed_needed), source=source)

    assert fault(ledger).status == C


def test_override_inherits_unset_confirmation_and_healing_threshold(
    open_ledger: OpenLedger,
) -> None:
    # The override only enables healing; the band comes from the global policy (-2, 2).
    ledger = open_ledger(
        Policy(
            confirmation_threshold=-2,
            healing_enabled=False,
            healing_threshold=2,
            overrides={"/sensors/lidar": {"healing_enabled": True}},
        )
    )
    assert trajectory(ledger, ["F", "F", "P", "P", "P", "P"], source="/sensors/lidar") == [
        (PF, -1), (C, -2), (C, -1), (C, 0), (C, 1), (H, 2)
    ]


def test_override_inherits_unset_healing_enabled(open_ledger: OpenLedger) -> None:
    # The override only moves the confirmation threshold; healing (enabled, 1) is global.
    ledger = open_ledger(
        Policy(
            confirmation_threshold=-1,
            healing_enabled=True,
            healing_threshold=1,
            overrides={"/sensors/lidar": {"confirmation_threshold": -2}},
        )
    )
    assert trajectory(ledger, ["F", "F", "P", "P", "P"], source="/sensors/lidar") == [
        (PF, -1), (C, -2), (C, -1), (C, 0), (H, 1)
    ]


def test_sources_without_override_keep_global_policy(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(
        Policy(
            confirmation_threshold=-2,
            healing_enabled=False,
            healing_threshold=2,
            overrides={"/sensors/lidar": {"healing_enabled": True}},
        )
    )
    assert trajectory(ledger, ["F", "F", "P", "P", "P", "P"], source="/motor") == [
        (PF, -1), (C, -2), (C, -1), (C, 0), (C, 1), (C, 2)
    ]


def test_stored_counter_clamped_to_reporting_sources_band_before_step(
    open_ledger: OpenLedger,
) -> None:
    ledger = open_ledger(
        Policy(confirmation_threshold=-5, overrides={"/fast": {"confirmation_threshold": -2}})
    )
    for i in range(5):
        failed(ledger, at(i), source="/slow")
    assert fault(ledger).debounce_counter == -5

    passed(ledger, at(10), source="/fast")

    # clamp -5 into [-2, 3] first, then +1
    assert (fault(ledger).status, fault(ledger).debounce_counter) == (C, -1)


def test_failed_step_result_clamped_to_reporting_sources_band(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(
        Policy(confirmation_threshold=-5, overrides={"/fast": {"confirmation_threshold": -2}})
    )
    failed(ledger, at(0), source="/slow")
    failed(ledger, at(1), source="/slow")
    assert (fault(ledger).status, fault(ledger).debounce_counter) == (PF, -2)

    failed(ledger, at(2), source="/fast")

    assert (fault(ledger).status, fault(ledger).debounce_counter) == (C, -2)


# --------------------------------------------------------------------------------------------
# §4.3 field rules
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("severities", "expected"),
    [
        pytest.param([1, 2], 2, id="raised_by_higher"),
        pytest.param([2, 0], 2, id="not_lowered_by_lower"),
        pytest.param([0, 1, 0], 1, id="max_of_all"),
        pytest.param([2, 3, 1], 3, id="critical_kept"),
    ],
)
def test_severity_is_max_of_failed_severities(
    open_ledger: OpenLedger, severities: list[int], expected: int
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-5))
    for i, severity in enumerate(severities):
        failed(ledger, at(i), severity=severity)
    assert fault(ledger).severity == expected


def test_passed_severity_does_not_raise_severity(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-5))
    failed(ledger, at(0), severity=1)
    passed(ledger, at(1), severity=3)
    assert fault(ledger).severity == 1


def test_severity_not_lowered_across_reactivation(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    failed(ledger, at(0), severity=2)
    clear(ledger)
    failed(ledger, at(10), severity=0)
    assert fault(ledger).severity == 2


@pytest.mark.parametrize(
    ("descriptions", "expected"),
    [
        pytest.param(["first"], "first", id="set_on_creation"),
        pytest.param(["first", ""], "first", id="empty_description_keeps_previous"),
        pytest.param(["first", "second"], "second", id="non_empty_description_replaces"),
        pytest.param(["", "second"], "second", id="empty_then_non_empty"),
        pytest.param(["first", "second", ""], "second", id="latest_non_empty_kept"),
    ],
)
def test_description_replaced_by_failed_with_non_empty_description(
    open_ledger: OpenLedger, descriptions: list[str], expected: str
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-5))
    for i, description in enumerate(descriptions):
        failed(ledger, at(i), description=description)
    assert fault(ledger).description == expected


def test_passed_description_is_ignored(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-5))
    failed(ledger, at(0), description="first")
    passed(ledger, at(1), description="all good again")
    assert fault(ledger).description == "first"


def test_reporting_sources_is_sorted_set_of_failed_sources(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-5))
    for i, source in enumerate(["/b", "/c", "/a", "/b"]):
        failed(ledger, at(i), source=source)
    assert fault(ledger).reporting_sources == ("/a", "/b", "/c")


def test_passed_source_not_added_to_reporting_sources(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-5))
    failed(ledger, at(0), source="/b")
    passed(ledger, at(1), source="/a")
    assert fault(ledger).reporting_sources == ("/b",)


def test_reporting_sources_never_pruned_across_clear_and_reactivation(
    open_ledger: OpenLedger,
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    failed(ledger, at(0), source="/b")
    failed(ledger, at(1), source="/a")
    clear(ledger)
    failed(ledger, at(10), source="/c")
    assert fault(ledger).reporting_sources == ("/a", "/b", "/c")


def test_occurrence_count_is_one_on_creation_and_not_raised_by_repeated_failed(
    open_ledger: OpenLedger,
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    for i in range(5):
        failed(ledger, at(i))
    assert fault(ledger).occurrence_count == 1


@pytest.mark.parametrize(
    ("steps", "expected"),
    [
        pytest.param(["F", "C", "F"], 2, id="one_reactivation"),
        pytest.param(["F", "C", "F", "F", "C", "F"], 3, id="two_reactivations"),
        pytest.param(["F", "C", "C", "F"], 2, id="double_clear_counts_once"),
        pytest.param(["F", "C", "P", "F"], 2, id="passed_on_cleared_does_not_count"),
    ],
)
def test_occurrence_count_incremented_by_reactivation_from_cleared(
    open_ledger: OpenLedger, steps: list[str], expected: int
) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    for i, step in enumerate(steps):
        apply_step(ledger, step, at(i))
    assert fault(ledger).occurrence_count == expected


def test_occurrence_count_not_raised_by_heal_and_reconfirm(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(
        Policy(confirmation_threshold=-1, healing_enabled=True, healing_threshold=1)
    )
    trajectory_seen = trajectory(ledger, ["F", "P", "P", "F", "F"])
    assert [status for status, _ in trajectory_seen] == [C, C, H, H, C]
    assert fault(ledger).occurrence_count == 1


def test_first_occurred_is_creation_time(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    failed(ledger, at(0))
    failed(ledger, at(5))
    passed(ledger, at(6))
    assert fault(ledger).first_occurred == at(0)


def test_first_and_last_occurred_set_to_reactivation_time(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    failed(ledger, at(0))
    failed(ledger, at(5))
    clear(ledger)

    failed(ledger, at(60))

    assert (fault(ledger).first_occurred, fault(ledger).last_occurred) == (at(60), at(60))


def test_last_occurred_moves_with_every_failed(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    failed(ledger, at(0))
    failed(ledger, at(7))
    failed(ledger, at(9))
    assert fault(ledger).last_occurred == at(9)


def test_last_occurred_not_moved_by_passed(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    failed(ledger, at(0))
    passed(ledger, at(5))
    assert fault(ledger).last_occurred == at(0)


def test_last_passed_is_none_until_first_passed(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    failed(ledger, at(0))
    failed(ledger, at(1))
    assert fault(ledger).last_passed is None


def test_last_passed_moves_with_every_passed_on_active_fault(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    failed(ledger, at(0))
    passed(ledger, at(3))
    passed(ledger, at(8))
    assert fault(ledger).last_passed == at(8)


def test_last_passed_not_moved_by_passed_on_cleared_fault(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-1))
    failed(ledger, at(0))
    passed(ledger, at(3))
    clear(ledger)
    passed(ledger, at(8))
    assert fault(ledger).last_passed == at(3)


def test_times_are_returned_as_utc(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    plus_two = timezone(timedelta(hours=2))
    reported_at = datetime(2026, 11, 22, 1, 30, tzinfo=plus_two)  # 23:30 UTC
    failed(ledger, reported_at)
    passed(ledger, reported_at + timedelta(seconds=1))

    f = fault(ledger)
    for moment in (f.first_occurred, f.last_occurred, f.last_passed):
        assert moment is not None
        assert moment.utcoffset() == timedelta(0)
    assert f.first_occurred == datetime(2026, 11, 21, 23, 30, tzinfo=UTC)


def test_sub_second_report_time_is_kept(open_ledger: OpenLedger) -> None:
    ledger = open_ledger(Policy(confirmation_threshold=-3))
    moment = T0 + timedelta(microseconds=123_456)
    failed(ledger, moment)
    assert fault(ledger).last_occurred == moment
