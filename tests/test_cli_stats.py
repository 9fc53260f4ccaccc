"""`faultledger stats`: the table, JSON and CSV say what ``FaultLedger.stats`` says; globs,
shift-id bounds and the calendar setting work; bad input is one clear line and exit 2.

Real SQLite files in tmp_path; the CLI in-process (typer's CliRunner) and, for the entry
point's error handling, as a subprocess.
"""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from faultledger.domain.stat_rows import StatsRow
from faultledger.reports.shift import duration
from tests.cli_stats_scenario import (
    ARM1,
    ARM2,
    AS_OF,
    AS_OF_TEXT,
    GLOB,
    MORNING,
    NIGHT,
    PREVIOUS_NIGHT,
    Scenario,
    assert_clean_error,
    berlin,
    build,
    invoke,
    presses,
)

CLI = [sys.executable, "-m", "faultledger.cli.main"]
RANGE = ["--since", PREVIOUS_NIGHT, "--until", MORNING, "--as-of", AS_OF_TEXT]


@pytest.fixture
def scenario(tmp_path: Path) -> Scenario:
    return build(tmp_path)


def expected(scenario: Scenario, **query: Any) -> list[StatsRow]:
    with scenario.ledger() as ledger:
        return ledger.stats(**{"since": PREVIOUS_NIGHT, "until": MORNING, **query},
                            calendar=scenario.calendar, as_of=AS_OF)


def table_rows(output: str) -> dict[str, list[str]]:
    """Data rows of a rich table, keyed by their first cell (plus the group cells)."""
    rows: dict[str, list[str]] = {}
    for line in output.splitlines():
        if line.startswith("│"):
            cells = [cell.strip() for cell in line.split("│")[1:-1]]
            rows[cells[0]] = cells
    return rows


def as_csv_cells(row: dict[str, Any]) -> dict[str, str]:
    return {key: "" if value is None else str(value) for key, value in row.items()}


def test_the_table_shows_the_main_figures_of_every_shift(scenario: Scenario) -> None:
    result = invoke("stats", *scenario.cli(*RANGE))
    assert result.exit_code == 0, result.stderr
    shown = table_rows(result.stdout)
    rows = expected(scenario)
    assert [r.period.id for r in rows] == [PREVIOUS_NIGHT, "2026-11-21/morning",
                                           "2026-11-21/afternoon", NIGHT, MORNING]
    assert list(shown) == [r.period.id for r in rows]
    for row in rows:
        cells = shown[row.period.id]
        assert cells[2:] == [
            str(row.estops), str(row.aborted_goals), str(row.activations),
            str(row.failed_reports), str(row.confirmations), str(row.heals), str(row.clears),
            duration(row.active_seconds),
            duration(row.mttr_seconds), f"{row.flood_percent:.1f}", str(row.chattering_codes),
            str(row.stale_codes)]
    night = shown[NIGHT]
    assert night[1] == "2026-11-21 22:00–2026-11-22 06:00"  # local time of the calendar
    assert night[4] == str(presses(berlin(21, 22, 0), berlin(22, 6, 0)))  # activations
    assert "Europe/Berlin" in result.stdout


def test_json_carries_every_field_of_each_row(scenario: Scenario) -> None:
    result = invoke("stats", "--json", "--group-by", "code", *scenario.cli(*RANGE))
    assert result.exit_code == 0, result.stderr
    rows = expected(scenario, group_by=["code"])
    assert json.loads(result.stdout) == [row.as_dict() for row in rows]
    assert len(rows) > 5


def test_csv_carries_every_field_with_a_header(scenario: Scenario) -> None:
    result = invoke("stats", "--csv", "--by", "hour", "--group-by", "severity",
                    *scenario.cli("--since", NIGHT, "--until", NIGHT, "--as-of", AS_OF_TEXT))
    assert result.exit_code == 0, result.stderr
    rows = expected(scenario, by="hour", since=NIGHT, until=NIGHT, group_by=["severity"])
    parsed = list(csv.DictReader(io.StringIO(result.stdout)))
    assert parsed == [as_csv_cells(row.as_dict()) for row in rows]
    assert list(parsed[0]) == list(rows[0].as_dict())


def test_csv_without_rows_still_has_the_header(scenario: Scenario) -> None:
    result = invoke("stats", "--csv", "--code", "NO_SUCH_*", "--group-by", "code",
                    *scenario.cli(*RANGE))
    assert result.exit_code == 0, result.stderr
    header = result.stdout.splitlines()
    assert len(header) == 1
    assert header[0].startswith("period,period_name,production_day,start,end,code,")


def test_code_glob_selects_the_emergency_stops_only(scenario: Scenario) -> None:
    result = invoke("stats", "--json", "--code", GLOB, "--group-by", "code",
                    *scenario.cli(*RANGE))
    assert result.exit_code == 0, result.stderr
    data = json.loads(result.stdout)
    assert data == [r.as_dict() for r in expected(scenario, codes=[GLOB], group_by=["code"])]
    assert {row["code"] for row in data} == {ARM1, ARM2}  # not HW_ARM1_EMERGENCY_STOP_RESET
    night = {row["code"]: row["activations"] for row in data if row["period"] == NIGHT}
    start, end = berlin(21, 22, 0), berlin(22, 6, 0)
    assert night == {ARM1: presses(start, end, ARM1), ARM2: presses(start, end, ARM2)}
    assert all(night.values())


def test_repeated_code_globs_select_any_of_them(scenario: Scenario) -> None:
    result = invoke("stats", "--json", "--code", GLOB, "--code", "LIDAR_*",
                    *scenario.cli(*RANGE))
    assert result.exit_code == 0, result.stderr
    data = json.loads(result.stdout)
    assert data == [r.as_dict() for r in expected(scenario, codes=[GLOB, "LIDAR_*"])]
    start, end = berlin(21, 22, 0), berlin(22, 6, 0)
    assert [row["activations"] for row in data if row["period"] == NIGHT] == [
        presses(start, end, GLOB) + presses(start, end, "LIDAR_*")]


def test_shift_ids_bound_the_range_to_that_shift(scenario: Scenario) -> None:
    result = invoke("stats", "--json", "--by", "hour",
                    *scenario.cli("--since", NIGHT, "--until", NIGHT, "--as-of", AS_OF_TEXT))
    assert result.exit_code == 0, result.stderr
    data = json.loads(result.stdout)
    assert len(data) == 8
    assert data[0]["start"] == berlin(21, 22, 0).isoformat()
    assert data[-1]["end"] == berlin(22, 6, 0).isoformat()
    assert sum(row["activations"] for row in data) == presses(berlin(21, 22, 0),
                                                               berlin(22, 6, 0))


def test_dates_and_local_date_times_are_bounds_too(scenario: Scenario) -> None:
    result = invoke("stats", "--json", "--by", "day",
                    *scenario.cli("--since", "2026-11-21", "--until", "2026-11-22T06:00",
                                  "--as-of", AS_OF_TEXT))
    assert result.exit_code == 0, result.stderr
    data = json.loads(result.stdout)
    assert [row["period"] for row in data] == ["2026-11-21", "2026-11-22"]
    assert data[0]["start"] == berlin(21, 0, 0).isoformat()
    assert data[1]["end"] == berlin(22, 6, 0).isoformat()


def test_the_config_files_shifts_setting_is_the_default_calendar(
    scenario: Scenario, tmp_path: Path
) -> None:
    config = tmp_path / "faultledger.yaml"
    config.write_text(f"shifts: {scenario.shifts}\n", encoding="utf-8")
    result = invoke("stats", "--json", "--config", str(config), "--db", scenario.url, *RANGE)
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout) == [r.as_dict() for r in expected(scenario)]


def test_without_a_calendar_the_default_utc_shifts_apply(scenario: Scenario) -> None:
    result = invoke("stats", "--json", "--db", scenario.url, "--since", "2026-11-21/night",
                    "--until", "2026-11-21/night", "--as-of", "2026-11-23")
    assert result.exit_code == 0, result.stderr
    [row] = json.loads(result.stdout)
    assert (row["start"], row["end"]) == ("2026-11-21T22:00:00+00:00",
                                          "2026-11-22T06:00:00+00:00")


@pytest.mark.parametrize(("args", "words"), [
    (["--by", "week"], ["by must be one of shift, day, hour, 10min", "'week'"]),
    (["--since", "yesterday"], ["--since must be", "'yesterday'"]),
    (["--until", "2026-11-21/lunch"], ["until:", "no shift 'lunch'"]),
    (["--since", "2026-11-22", "--until", "2026-11-21"], ["must be before until"]),
    (["--group-by", "robot"], ["group_by", "robot"]),
    (["--group-by", "code", "--group-by", "code"], ["distinct"]),
    (["--as-of", "soon"], ["--as-of must be", "'soon'"]),
    (["--json", "--csv"], ["choose one of --json and --csv"]),
])
def test_bad_input_is_one_clear_line_and_exit_2(
    scenario: Scenario, args: list[str], words: list[str]
) -> None:
    result = invoke("stats", *scenario.cli(*args))
    assert_clean_error(result, *words)
    assert result.exit_code == 2


def test_a_bad_calendar_file_is_named(scenario: Scenario, tmp_path: Path) -> None:
    broken = tmp_path / "broken.yaml"
    broken.write_text("timezone: Mars/Olympus\nshifts: []\n", encoding="utf-8")
    result = invoke("stats", "--db", scenario.url, "--shifts", str(broken))
    assert_clean_error(result, "shift calendar", str(broken), "Mars/Olympus")


def test_a_missing_database_is_not_created(tmp_path: Path) -> None:
    missing = tmp_path / "missing.db"
    result = invoke("stats", "--db", f"sqlite:///{missing}")
    assert_clean_error(result, "does not exist")
    assert not missing.exists()


def test_the_installed_entry_point_prints_no_traceback(scenario: Scenario) -> None:
    done = subprocess.run([*CLI, "stats", *scenario.cli("--by", "fortnight")],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert "by must be one of" in done.stderr
    done = subprocess.run([*CLI, "stats", "--json", *scenario.cli(*RANGE)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == [r.as_dict() for r in expected(scenario)]
