"""Goal figures on the command line: `faultledger stats` (table, JSON, CSV, `--group-by
action`) and `faultledger report-shift` (aborted goals per shift next to the e-stops, with the
change against the previous shift, in the terminal and the HTML file).

The scenario (tests/cli_stats_scenario.py) scripts the goals; expected figures come from the
script and from ``FaultLedger.stats``.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pytest

from faultledger.domain.stat_rows import StatsRow
from tests.cli_stats_scenario import (
    AS_OF,
    AS_OF_TEXT,
    MORNING,
    NAV,
    NIGHT,
    PICK,
    PREVIOUS_NIGHT,
    Scenario,
    assert_clean_error,
    berlin,
    build,
    goals,
    invoke,
    presses,
)

RANGE = ["--since", PREVIOUS_NIGHT, "--until", MORNING, "--as-of", AS_OF_TEXT]
NIGHT_START, NIGHT_END = berlin(21, 22, 0), berlin(22, 6, 0)
PREVIOUS_START, PREVIOUS_END = berlin(20, 22, 0), berlin(21, 6, 0)


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> Scenario:
    return build(tmp_path_factory.mktemp("goals"))


def rich_rows(output: str, title: str | None = None) -> list[list[str]]:
    """Data rows of the (first) rich table, or of the one printed under ``title``."""
    lines = output.splitlines()
    start = 0 if title is None else next(i for i, line in enumerate(lines)
                                         if line.startswith(title))
    rows: list[list[str]] = []
    for line in lines[start:]:
        if line.startswith("└"):
            break
        if line.startswith("│"):
            rows.append([cell.strip() for cell in line.split("│")[1:-1]])
    return rows


def header(output: str) -> list[str]:
    line = next(line for line in output.splitlines() if line.startswith("┃"))
    return [cell.strip() for cell in line.split("┃")[1:-1]]


def expected(scenario: Scenario, **query: object) -> list[StatsRow]:
    with scenario.ledger() as ledger:
        return ledger.stats(**{"since": PREVIOUS_NIGHT, "until": MORNING,  # type: ignore[arg-type]
                               **query}, calendar=scenario.calendar, as_of=AS_OF)


def test_the_table_shows_aborted_goals_next_to_activations(scenario: Scenario) -> None:
    result = invoke("stats", *scenario.cli(*RANGE))
    assert result.exit_code == 0, result.stderr
    assert header(result.stdout)[2:6] == ["e-stops", "aborted goals", "activations", "failed"]
    shown = {row[0]: row for row in rich_rows(result.stdout)}
    assert shown[NIGHT][3:5] == [str(goals(NIGHT_START, NIGHT_END)),
                                 str(presses(NIGHT_START, NIGHT_END))]
    assert shown[PREVIOUS_NIGHT][3] == str(goals(PREVIOUS_START, PREVIOUS_END)) == "1"
    assert shown[NIGHT][3] == "3"  # the repeat of night-1 is counted once


def test_json_and_csv_carry_all_three_goal_figures(scenario: Scenario) -> None:
    rows = expected(scenario)
    result = invoke("stats", "--json", *scenario.cli(*RANGE))
    assert result.exit_code == 0, result.stderr
    parsed = json.loads(result.stdout)
    assert parsed == [row.as_dict() for row in rows]
    night = next(r for r in parsed if r["period"] == NIGHT)
    assert (night["aborted_goals"], night["canceled_goals"], night["succeeded_goals"]) == (
        goals(NIGHT_START, NIGHT_END), goals(NIGHT_START, NIGHT_END, "CANCELED"),
        goals(NIGHT_START, NIGHT_END, "SUCCEEDED")) == (3, 1, 1)
    result = invoke("stats", "--csv", *scenario.cli(*RANGE))
    assert result.exit_code == 0, result.stderr
    table = list(csv.DictReader(io.StringIO(result.stdout)))
    assert list(table[0])[-6:-3] == ["aborted_goals", "canceled_goals", "succeeded_goals"]
    assert [(r["period"], r["aborted_goals"]) for r in table] == [
        (row.period.id, str(row.aborted_goals)) for row in rows]


def test_group_by_action_shows_the_goal_figures_per_action(scenario: Scenario) -> None:
    result = invoke("stats", "--group-by", "action", *scenario.cli(*RANGE))
    assert result.exit_code == 0, result.stderr
    assert header(result.stdout) == ["period", "local time (Europe/Berlin)", "action",
                                     "aborted goals", "canceled goals", "succeeded goals"]
    shown = [(row[0], row[2], row[3:]) for row in rich_rows(result.stdout)]
    assert (NIGHT, NAV, ["3", "0", "0"]) in shown
    assert (NIGHT, PICK, ["0", "1", "1"]) in shown
    assert (PREVIOUS_NIGHT, NAV, ["1", "0", "1"]) in shown
    json_result = invoke("stats", "--json", "--group-by", "action", "--group-by", "source",
                         *scenario.cli(*RANGE))
    assert json_result.exit_code == 0, json_result.stderr
    parsed = json.loads(json_result.stdout)
    assert parsed == [r.as_dict() for r in expected(scenario, group_by=["action", "source"])]
    assert {(r["period"], r["action"], r["source"], r["aborted_goals"]) for r in parsed} >= {
        (NIGHT, NAV, "/bt_navigator", 3), (MORNING, PICK, "/arm_server", 1)}
    assert all(r["activations"] == 0 and r["failed_reports"] == 0 for r in parsed)


def test_action_with_code_is_one_clear_line(scenario: Scenario) -> None:
    result = invoke("stats", "--group-by", "action", "--group-by", "code", *scenario.cli())
    assert_clean_error(result, "group_by action combines only with source")


def test_report_shift_compares_aborted_goals_with_the_previous_night(
    scenario: Scenario, tmp_path: Path
) -> None:
    html = tmp_path / "night.html"
    result = invoke("report-shift", *scenario.cli(NIGHT, "--as-of", AS_OF_TEXT, "--html",
                                                  str(html)))
    assert result.exit_code == 0, result.stderr
    figures = {row[0]: row[1:] for row in rich_rows(result.stdout, "key figures")}
    assert list(figures)[:4] == ["e-stops", "aborted goals", "activations (all faults)",
                                 "failed reports"]
    assert figures["aborted goals"] == ["3", "1", "+2", "+200.0 %"]
    hours = rich_rows(result.stdout, "per hour")
    with scenario.ledger() as ledger:
        per_hour = ledger.stats("hour", NIGHT, NIGHT, calendar=scenario.calendar, as_of=AS_OF)
    assert [row[3] for row in hours] == [str(r.aborted_goals) for r in per_hour]
    assert sum(int(row[3]) for row in hours) == 3
    page = html.read_text(encoding="utf-8")
    assert ('<td class="text">aborted goals</td><td>3</td><td>1</td>'
            '<td class="worse">+2</td><td class="worse">+200.0 %</td>') in page
    assert "<th>aborted goals</th>" in page  # the per-hour table


def test_report_shift_of_a_shift_without_goals_says_zero(scenario: Scenario) -> None:
    result = invoke("report-shift", *scenario.cli("2026-11-21/afternoon", "--as-of",
                                                  AS_OF_TEXT))
    assert result.exit_code == 0, result.stderr
    figures = {row[0]: row[1:] for row in rich_rows(result.stdout, "key figures")}
    assert figures["aborted goals"] == ["0", "0", "±0", "-"]
