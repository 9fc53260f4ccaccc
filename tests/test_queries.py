"""SPEC §4.6: list filters (status, severity), get in any status, list for an entity."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from datetime import UTC, datetime, timedelta

import pytest

from faultledger import Fault, FaultLedger, FaultStatus, Policy

OpenLedger = Callable[..., FaultLedger]

T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)

ALL_STATUSES = ("PREFAILED", "PREPASSED", "CONFIRMED", "HEALED", "CLEARED")

# code -> (status, severity) of the fault the `ledger` fixture builds
POPULATION = {
    "CONFIRMED_ERROR": (FaultStatus.CONFIRMED, 2),
    "CONFIRMED_CRITICAL": (FaultStatus.CONFIRMED, 3),
    "PREFAILED_WARN": (FaultStatus.PREFAILED, 1),
    "PREPASSED_WARN": (FaultStatus.PREPASSED, 1),
    "HEALED_ERROR": (FaultStatus.HEALED, 2),
    "CLEARED_INFO": (FaultStatus.CLEARED, 0),
}
CONFIRMED_ONLY = ["CONFIRMED_CRITICAL", "CONFIRMED_ERROR"]


class Clock:
    """Hands out increasing report times, one second apart."""

    def __init__(self) -> None:
        self.ticks = 0

    def __call__(self) -> datetime:
        self.ticks += 1
        return T0 + timedelta(seconds=self.ticks)


def report(
    ledger: FaultLedger,
    clock: Clock,
    code: str,
    event_type: str,
    severity: int = 0,
    source: str = "/motor",
) -> None:
    result = ledger.report(
        code, event_type, severity=severity, description="", source_id=source, at=clock()
    )
    assert result.accepted, result.message


def codes(faults: list[Fault]) -> list[str]:
    return sorted(f.fault_code for f in faults)


def fault(ledger: FaultLedger, code: str) -> Fault:
    found = ledger.get_fault(code)
    assert found is not None, f"{code} should exist"
    return found


@pytest.fixture
def ledger(open_ledger: OpenLedger) -> FaultLedger:
    """One fault in every status (confirmation at -3, healing at +3)."""
    ledger = open_ledger(
        Policy(confirmation_threshold=-3, healing_enabled=True, healing_threshold=3)
    )
    clock = Clock()
    for _ in range(3):
        report(ledger, clock, "CONFIRMED_ERROR", "FAILED", severity=2)
    report(ledger, clock, "CONFIRMED_CRITICAL", "FAILED", severity=3)
    report(ledger, clock, "PREFAILED_WARN", "FAILED", severity=1)
    report(ledger, clock, "PREPASSED_WARN", "FAILED", severity=1)
    report(ledger, clock, "PREPASSED_WARN", "PASSED")
    report(ledger, clock, "PREPASSED_WARN", "PASSED")
    for _ in range(3):
        report(ledger, clock, "HEALED_ERROR", "FAILED", severity=2)
    for _ in range(6):
        report(ledger, clock, "HEALED_ERROR", "PASSED")
    report(ledger, clock, "CLEARED_INFO", "FAILED", severity=0)
    cleared = ledger.clear("CLEARED_INFO", actor="test:operator", reason="")
    assert cleared.success, cleared.message
    return ledger


def test_population_has_one_fault_per_status(ledger: FaultLedger) -> None:
    # guards the fixture the other tests rely on
    found = {code: fault(ledger, code) for code in POPULATION}
    assert {code: (f.status, f.severity) for code, f in found.items()} == POPULATION


@pytest.mark.parametrize(
    ("statuses", "expected"),
    [
        pytest.param((), CONFIRMED_ONLY, id="empty_means_confirmed_only"),
        pytest.param(["CONFIRMED"], CONFIRMED_ONLY, id="confirmed"),
        pytest.param(["PREFAILED"], ["PREFAILED_WARN"], id="prefailed"),
        pytest.param(["PREPASSED"], ["PREPASSED_WARN"], id="prepassed"),
        pytest.param(["HEALED"], ["HEALED_ERROR"], id="healed"),
        pytest.param(["CLEARED"], ["CLEARED_INFO"], id="cleared"),
        pytest.param(("PREFAILED", "PREPASSED"), ["PREFAILED_WARN", "PREPASSED_WARN"],
                     id="two_statuses_union"),
        pytest.param(ALL_STATUSES, sorted(POPULATION), id="all_statuses"),
        pytest.param(["CONFIRMED", "CONFIRMED"], CONFIRMED_ONLY, id="repeated_status_once"),
        pytest.param(["NOT_A_STATUS"], CONFIRMED_ONLY, id="only_unknown_means_confirmed_only"),
        pytest.param(["bogus", "", "PENDING"], CONFIRMED_ONLY,
                     id="several_unknown_mean_confirmed_only"),
        pytest.param(["NOT_A_STATUS", "CLEARED"], ["CLEARED_INFO"],
                     id="unknown_ignored_next_to_known"),
        pytest.param([FaultStatus.HEALED], ["HEALED_ERROR"], id="enum_member_accepted"),
    ],
)
def test_list_faults_status_filter(
    ledger: FaultLedger, statuses: Sequence[str], expected: list[str]
) -> None:
    assert codes(ledger.list_faults(statuses=statuses)) == expected


def test_list_faults_default_is_confirmed_only(ledger: FaultLedger) -> None:
    assert codes(ledger.list_faults()) == CONFIRMED_ONLY


@pytest.mark.parametrize(
    ("statuses", "severity", "expected"),
    [
        pytest.param((), 2, ["CONFIRMED_ERROR"], id="error_among_confirmed"),
        pytest.param((), 3, ["CONFIRMED_CRITICAL"], id="critical_among_confirmed"),
        pytest.param((), 1, [], id="no_confirmed_warn"),
        pytest.param(ALL_STATUSES, 2, ["CONFIRMED_ERROR", "HEALED_ERROR"], id="error_any_status"),
        pytest.param(ALL_STATUSES, 1, ["PREFAILED_WARN", "PREPASSED_WARN"], id="warn_any_status"),
        pytest.param(ALL_STATUSES, 0, ["CLEARED_INFO"], id="info_any_status"),
        pytest.param(ALL_STATUSES, None, sorted(POPULATION), id="none_means_any_severity"),
    ],
)
def test_list_faults_severity_filter_is_exact(
    ledger: FaultLedger, statuses: Sequence[str], severity: int | None, expected: list[str]
) -> None:
    assert codes(ledger.list_faults(statuses=statuses, severity=severity)) == expected


def test_list_faults_returns_fault_values(ledger: FaultLedger) -> None:
    faults = ledger.list_faults()
    assert all(isinstance(f, Fault) for f in faults)
    assert {f.status for f in faults} == {FaultStatus.CONFIRMED}


@pytest.mark.parametrize(("code", "status_and_severity"), list(POPULATION.items()))
def test_get_fault_returns_fault_in_any_status(
    ledger: FaultLedger, code: str, status_and_severity: tuple[FaultStatus, int]
) -> None:
    found = ledger.get_fault(code)
    assert isinstance(found, Fault)
    assert (found.fault_code, (found.status, found.severity)) == (code, status_and_severity)


def test_get_fault_unknown_is_none(ledger: FaultLedger) -> None:
    assert ledger.get_fault("NEVER_REPORTED") is None


# --------------------------------------------------------------------------------------------
# list_faults_for_entity
# --------------------------------------------------------------------------------------------


@pytest.fixture
def entity_ledger(open_ledger: OpenLedger) -> FaultLedger:
    """Faults reported from various sources; confirmation at -2 so single reports stay PREFAILED."""
    ledger = open_ledger(Policy(confirmation_threshold=-2))
    clock = Clock()
    report(ledger, clock, "LIDAR_TIMEOUT", "FAILED", source="/robot/sensors/lidar")
    report(ledger, clock, "LIDAR_BARE", "FAILED", source="lidar")
    report(ledger, clock, "LIDAR_OLD", "FAILED", source="/robot/lidar")
    cleared = ledger.clear("LIDAR_OLD", actor="test:operator", reason="")
    assert cleared.success, cleared.message
    report(ledger, clock, "LIDAR_FRONT_DIRTY", "FAILED", source="/robot/sensors/lidar_front")
    report(ledger, clock, "MYLIDAR_FAULT", "FAILED", source="/robot/mylidar")
    report(ledger, clock, "LIDAR_MOUNT_LOOSE", "FAILED", source="/robot/lidar/mount")
    report(ledger, clock, "MOTOR_OVERHEAT", "FAILED", source="/motor")
    report(ledger, clock, "MOTOR_OVERHEAT", "PASSED", source="/robot/sensors/lidar")
    report(ledger, clock, "SHARED_BUS", "FAILED", source="/motor")
    report(ledger, clock, "SHARED_BUS", "FAILED", source="/robot/sensors/lidar")
    return ledger


@pytest.mark.parametrize(
    ("entity", "expected"),
    [
        pytest.param("lidar", ["LIDAR_BARE", "LIDAR_OLD", "LIDAR_TIMEOUT", "SHARED_BUS"],
                     id="name_matches_equal_source_and_path_ending"),
        pytest.param("/robot/sensors/lidar", ["LIDAR_TIMEOUT", "SHARED_BUS"],
                     id="full_path_matches_equal_source"),
        pytest.param("sensors/lidar", ["LIDAR_TIMEOUT", "SHARED_BUS"],
                     id="partial_path_matches_path_ending"),
        pytest.param("mount", ["LIDAR_MOUNT_LOOSE"], id="last_segment_matches"),
        pytest.param("motor", ["MOTOR_OVERHEAT", "SHARED_BUS"], id="motor"),
        pytest.param("lidar_front", ["LIDAR_FRONT_DIRTY"], id="underscore_name"),
        pytest.param("front", [], id="name_suffix_without_slash_does_not_match"),
        pytest.param("idar", [], id="partial_segment_does_not_match"),
        pytest.param("robot", [], id="leading_segment_does_not_match"),
        pytest.param("camera", [], id="unknown_entity_has_no_faults"),
    ],
)
def test_list_faults_for_entity(
    entity_ledger: FaultLedger, entity: str, expected: list[str]
) -> None:
    assert codes(entity_ledger.list_faults_for_entity(entity)) == expected


def test_list_faults_for_entity_includes_every_status(entity_ledger: FaultLedger) -> None:
    statuses = {f.fault_code: f.status for f in entity_ledger.list_faults_for_entity("lidar")}
    assert statuses == {
        "LIDAR_BARE": FaultStatus.PREFAILED,
        "LIDAR_OLD": FaultStatus.CLEARED,
        "LIDAR_TIMEOUT": FaultStatus.PREFAILED,
        "SHARED_BUS": FaultStatus.CONFIRMED,
    }


def test_passed_source_does_not_link_fault_to_entity(entity_ledger: FaultLedger) -> None:
    matched = codes(entity_ledger.list_faults_for_entity("/robot/sensors/lidar"))
    assert "MOTOR_OVERHEAT" not in matched
