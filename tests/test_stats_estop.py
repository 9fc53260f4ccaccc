"""E-stops per shift (the issue's scenario): presses of an emergency stop counted per shift
instance of a Europe/Berlin calendar, with a healing and with the default policy."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable, Iterator, Sequence
from datetime import UTC, date, datetime, timedelta
from pathlib import Path
from zoneinfo import ZoneInfo

import pytest

from faultledger import FaultLedger, Policy
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import StatsRow
from faultledger.errors import InvalidInputError
from tests.cli_stats_scenario import CALENDAR_YAML as SHIFTS_YAML

BERLIN = ZoneInfo("Europe/Berlin")
CALENDAR = ShiftCalendar.model_validate({
    "timezone": "Europe/Berlin",
    "shifts": [
        {"name": "morning", "start": "06:00", "end": "14:00"},
        {"name": "afternoon", "start": "14:00", "end": "22:00"},
        {"name": "night", "start": "22:00", "end": "06:00"},
    ],
})
ESTOP = "HW_ARM1_EMERGENCY_STOP"
GLOB = "HW_*_EMERGENCY_STOP"
NIGHT, MORNING = "2026-11-21/night", "2026-11-22/morning"
SHIFT_SECONDS = 8 * 3600.0


def berlin(day: int, hour: int, minute: int, second: int = 0, micro: int = 0) -> datetime:
    """A local Berlin wall-clock time in November 2026 (UTC+1), as aware UTC."""
    return datetime(2026, 11, day, hour, minute, second, micro, tzinfo=BERLIN).astimezone(UTC)


# (pressed at, held for seconds, severity)
NIGHT_PRESSES = [
    (berlin(21, 22, 10), 30.0, 3),
    (berlin(21, 23, 30, 15), 45.0, 2),
    (berlin(22, 1, 2, 3, 250_000), 120.0, 3),
    (berlin(22, 2, 45), 10.0, 2),
    (berlin(22, 5, 59, 30), 25.0, 3),    # released 05:59:55, still in the night
]
MORNING_PRESSES = [
    (berlin(22, 6, 0), 40.0, 2),         # exactly 06:00: the morning's, not the night's
    (berlin(22, 9, 40), 75.0, 3),
]
AS_OF = berlin(22, 13, 0)
HEALING = Policy(healing_enabled=True, healing_threshold=0)
"""One PASSED heals a fault confirmed by one FAILED: the counter goes -1 → 0 ≥ 0. (With
healing_threshold=1 a release would need two PASSED reports: -1 → 0 → 1.)"""


def press(ledger: FaultLedger, at: datetime, held: float, severity: int) -> None:
    assert ledger.report(ESTOP, "FAILED", severity, "e-stop pressed", "/arm1/estop",
                         at=at).accepted
    assert ledger.report(ESTOP, "PASSED", 0, "", "/arm1/estop",
                         at=at + timedelta(seconds=held)).accepted


def noise(ledger: FaultLedger) -> None:
    """Faults the glob must not select."""
    for code in ("LIDAR_TIMEOUT", "HW_ARM1_EMERGENCY_STOP_RESET", "hw_arm2_emergency_stop"):
        assert ledger.report(code, "FAILED", 2, "", "/other", at=berlin(21, 23, 0)).accepted
        assert ledger.report(code, "PASSED", 0, "", "/other", at=berlin(22, 7, 0)).accepted
        assert ledger.report(code, "FAILED", 2, "", "/other", at=berlin(22, 7, 5)).accepted


def shift_stats(ledger: FaultLedger, group_by: Sequence[str] = ()) -> list[StatsRow]:
    """Shift ids as since/until: the night's start and the morning's end."""
    return ledger.stats(by="shift", since=NIGHT, until=MORNING, codes=[GLOB],
                        group_by=group_by, calendar=CALENDAR, as_of=AS_OF)


def figures(row: StatsRow) -> dict[str, object]:
    return {name: getattr(row, name) for name in row.__dataclass_fields__
            if name not in ("period", "group", "complete")}


def approx_figures(expected: dict[str, object]) -> dict[str, object]:
    return {k: pytest.approx(v, rel=1e-9, abs=1e-6) if isinstance(v, float) else v
            for k, v in expected.items()}


COMMON = {"occurrences": 0, "flood_windows": 0, "flood_seconds": 0.0, "flood_percent": 0.0,
          "chattering_codes": 0, "stale_codes": 0, "top10_share": 1.0, "aborted_goals": 0,
          "canceled_goals": 0, "succeeded_goals": 0, "acknowledgements": 0,
          "mtta_seconds": None, "shelved_seconds": 0.0}


@pytest.fixture
def opened(db_url: str) -> Iterator[Callable[[Policy], FaultLedger]]:
    ledgers: list[FaultLedger] = []

    def _open(policy: Policy) -> FaultLedger:
        ledger = FaultLedger.open(db_url, policy=policy, background=False)
        ledgers.append(ledger)
        return ledger

    yield _open
    for ledger in ledgers:
        ledger.close()


def test_the_periods_are_the_two_shift_instances_named_by_their_production_day(
    opened: Callable[[Policy], FaultLedger]
) -> None:
    ledger = opened(HEALING)
    rows = shift_stats(ledger)
    assert [(r.period.id, r.period.name, r.period.production_day) for r in rows] == [
        (NIGHT, "night", date(2026, 11, 21)), (MORNING, "morning", date(2026, 11, 22))]
    assert [(r.period.start, r.period.end) for r in rows] == [
        (berlin(21, 22, 0), berlin(22, 6, 0)), (berlin(22, 6, 0), berlin(22, 14, 0))]
    assert all(r.group == {} for r in rows)


def test_with_healing_each_press_is_one_activation_confirmation_heal_and_repair(
    opened: Callable[[Policy], FaultLedger]
) -> None:
    ledger = opened(HEALING)
    noise(ledger)
    for at, held, severity in NIGHT_PRESSES + MORNING_PRESSES:
        press(ledger, at, held, severity)

    night, morning = shift_stats(ledger)
    night_held = [held for _, held, _ in NIGHT_PRESSES]
    morning_held = [held for _, held, _ in MORNING_PRESSES]
    assert figures(night) == approx_figures({
        **COMMON, "failed_reports": 5, "passed_reports": 5, "activations": 5, "estops": 5,
        "occurrences": 1, "confirmations": 5, "heals": 5, "clears": 0,
        "active_seconds": sum(night_held), "repairs": 5,
        "mttr_seconds": sum(night_held) / 5, "mtbf_seconds": SHIFT_SECONDS / 5,
        "confirmations_per_10min": 5 / 48})
    assert figures(morning) == approx_figures({
        **COMMON, "failed_reports": 2, "passed_reports": 2, "activations": 2, "estops": 2,
        "confirmations": 2, "heals": 2, "clears": 0,
        "active_seconds": sum(morning_held), "repairs": 2,
        "mttr_seconds": sum(morning_held) / 2, "mtbf_seconds": SHIFT_SECONDS / 2,
        "confirmations_per_10min": 2 / 48})

    by_code = shift_stats(ledger, group_by=["code"])
    assert [(r.period.id, r.group, r.activations) for r in by_code] == [
        (NIGHT, {"code": ESTOP}, 5), (MORNING, {"code": ESTOP}, 2)]
    by_severity = shift_stats(ledger, group_by=["severity"])
    # A fact's severity is the fault's after the record: never lowered, so 3 from the first.
    assert [(r.period.id, r.group, r.activations) for r in by_severity] == [
        (NIGHT, {"severity": 3}, 5), (MORNING, {"severity": 3}, 2)]


def test_without_healing_the_stop_stays_confirmed_but_every_press_is_an_activation(
    opened: Callable[[Policy], FaultLedger]
) -> None:
    ledger = opened(Policy())
    noise(ledger)
    for at, held, severity in NIGHT_PRESSES:
        press(ledger, at, held, severity)
    cleared_at = berlin(22, 5, 59, 58)
    assert ledger.clear(ESTOP, actor="cli:alice", at=cleared_at).success
    for at, held, severity in MORNING_PRESSES:
        press(ledger, at, held, severity)

    night, morning = shift_stats(ledger)
    episode = (cleared_at - NIGHT_PRESSES[0][0]).total_seconds()
    assert figures(night) == approx_figures({
        **COMMON, "failed_reports": 5, "passed_reports": 5, "activations": 5, "estops": 5,
        "occurrences": 1, "confirmations": 1, "heals": 0, "clears": 1,
        "active_seconds": episode, "repairs": 1, "mttr_seconds": episode,
        "mtbf_seconds": SHIFT_SECONDS, "confirmations_per_10min": 1 / 48})
    # Reopened at 06:00 sharp by the first morning press; still open at AS_OF (13:00).
    assert figures(morning) == approx_figures({
        **COMMON, "failed_reports": 2, "passed_reports": 2, "activations": 2, "estops": 2,
        "occurrences": 1, "confirmations": 1, "heals": 0, "clears": 0,
        "active_seconds": 7 * 3600.0, "repairs": 0, "mttr_seconds": None,
        "mtbf_seconds": SHIFT_SECONDS, "confirmations_per_10min": 1 / 48})


def test_without_healing_and_without_a_clear_the_activations_are_still_five_and_two(
    opened: Callable[[Policy], FaultLedger]
) -> None:
    ledger = opened(Policy())
    for at, held, severity in NIGHT_PRESSES + MORNING_PRESSES:
        press(ledger, at, held, severity)
    night, morning = shift_stats(ledger)
    assert (night.activations, night.confirmations, night.heals, night.repairs) == (5, 1, 0, 0)
    assert (morning.activations, morning.confirmations, morning.occurrences) == (2, 0, 0)
    first = NIGHT_PRESSES[0][0]
    assert night.active_seconds == pytest.approx((berlin(22, 6, 0) - first).total_seconds())
    assert morning.active_seconds == pytest.approx(7 * 3600.0)


def all_codes(ledger: FaultLedger, **kwargs: object) -> list[StatsRow]:
    return ledger.stats(by="shift", since=NIGHT, until=MORNING, calendar=CALENDAR,
                        as_of=AS_OF, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("edge", [0, 1], ids=["whole-minutes", "partial-minutes"])
def test_estops_count_only_the_estop_codes_among_all_activations(
    opened: Callable[[Policy], FaultLedger], edge: int
) -> None:
    """Without a code filter (the per-minute sums path, and the facts path where a bound
    cuts a minute) the rows count every activation, and e-stops only for the e-stop codes:
    the noise codes (a RESET suffix, lower case, another fault) are activations, not e-stops."""
    ledger = opened(HEALING)
    noise(ledger)
    for at, held, severity in NIGHT_PRESSES + MORNING_PRESSES:
        press(ledger, at, held, severity)
    since = berlin(21, 22, 0) + timedelta(seconds=edge)
    night, morning = ledger.stats(by="shift", since=since, until=MORNING, calendar=CALENDAR,
                                  as_of=AS_OF)
    assert (night.estops, morning.estops) == (5, 2)
    assert (night.activations, morning.activations) == (5 + 3, 2 + 3)
    by_code = ledger.stats(by="shift", since=since, until=MORNING, calendar=CALENDAR,
                           as_of=AS_OF, group_by=["code"])
    assert {(r.period.id, r.group["code"]): r.estops for r in by_code if r.estops} == {
        (NIGHT, ESTOP): 5, (MORNING, ESTOP): 2}
    assert sum(r.estops for r in by_code) == 7


def test_the_estop_codes_are_configurable(db_url: str) -> None:
    """``estop_codes`` names what an e-stop is: here the plant's own code, not the bridge's."""
    with FaultLedger.open(db_url, policy=HEALING, background=False,
                          estop_codes=["PLC_*_ESTOP", "LIDAR_TIMEOUT"]) as ledger:
        noise(ledger)
        for at, held, severity in NIGHT_PRESSES:
            press(ledger, at, held, severity)
        assert ledger.report("PLC_CELL3_ESTOP", "FAILED", 3, "", "/plc",
                             at=berlin(21, 23, 5)).accepted
        night, morning = all_codes(ledger)
        # night: the PLC stop and LIDAR_TIMEOUT's first FAILED; morning: LIDAR_TIMEOUT again
        # after its PASSED at 07:00 (noise()). The bridge's HW_ARM1_EMERGENCY_STOP is none.
        assert (night.estops, morning.estops) == (2, 1)


@pytest.mark.parametrize("bad", [[], [""], "HW_*"])
def test_bad_estop_codes_are_refused(db_url: str, bad: object) -> None:
    with pytest.raises(InvalidInputError):
        FaultLedger.open(db_url, estop_codes=bad)  # type: ignore[arg-type]


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    """The real CLI in a subprocess, as an operator types it."""
    return subprocess.run([sys.executable, "-m", "faultledger.cli.main", *args],
                          capture_output=True, text=True, timeout=120, check=False)


def test_the_cli_prints_e_stops_per_shift_as_json(db_url: str, tmp_path: Path) -> None:
    with FaultLedger.open(db_url, policy=HEALING, background=False) as ledger:
        noise(ledger)
        for at, held, severity in NIGHT_PRESSES + MORNING_PRESSES:
            press(ledger, at, held, severity)
    shifts = tmp_path / "shifts.yaml"
    shifts.write_text(SHIFTS_YAML, encoding="utf-8")

    done = run_cli("stats", "--by", "shift", "--code", GLOB, "--json", "--db", db_url,
                   "--shifts", str(shifts), "--since", NIGHT, "--until", MORNING,
                   "--as-of", AS_OF.isoformat())
    assert done.returncode == 0, done.stderr
    rows = json.loads(done.stdout)
    assert [(r["period"], r["period_name"], r["production_day"]) for r in rows] == [
        (NIGHT, "night", "2026-11-21"), (MORNING, "morning", "2026-11-22")]
    assert [r["activations"] for r in rows] == [5, 2]
    assert [r["estops"] for r in rows] == [5, 2]
    assert [r["failed_reports"] for r in rows] == [5, 2]
    assert [r["confirmations"] for r in rows] == [5, 2]
    assert [r["heals"] for r in rows] == [5, 2]
    night_held = sum(held for _, held, _ in NIGHT_PRESSES)
    morning_held = sum(held for _, held, _ in MORNING_PRESSES)
    assert [r["active_seconds"] for r in rows] == [pytest.approx(night_held),
                                                   pytest.approx(morning_held)]
    assert [r["mttr_seconds"] for r in rows] == [pytest.approx(night_held / 5),
                                                 pytest.approx(morning_held / 2)]

    by_code = run_cli("stats", "--by", "shift", "--code", GLOB, "--group-by", "code",
                      "--json", "--db", db_url, "--shifts", str(shifts), "--since", NIGHT,
                      "--until", MORNING, "--as-of", AS_OF.isoformat())
    assert by_code.returncode == 0, by_code.stderr
    assert [(r["period"], r["code"], r["activations"]) for r in json.loads(by_code.stdout)] == [
        (NIGHT, ESTOP, 5), (MORNING, ESTOP, 2)]
