"""A newcomer's first hour: tables readable at 80 columns (under a real pseudo-terminal),
`--wide`, one time grammar for every command, `--db` plain paths and missing drivers, unknown
statuses, `show`'s clear reason, `--version`, and a shift report that explains itself.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from datetime import timedelta
from importlib.metadata import version
from pathlib import Path

import pytest

from faultledger import FaultLedger
from faultledger.reports import shift_html
from faultledger.reports.shift import GLOSSARY, build_report
from tests.cli_stats_scenario import (
    AS_OF,
    AS_OF_TEXT,
    NIGHT,
    Scenario,
    assert_clean_error,
    berlin,
    build,
    invoke,
)
from tests.test_safe_output import SGR, run_in_terminal

LONG = "HW_LEFT_ARM_SHOULDER_JOINT_EMERGENCY_STOP"
"""A 41-character code: it must never be split across lines."""
STATUSES = ("PREFAILED", "PREPASSED", "CONFIRMED", "HEALED", "CLEARED")


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> Scenario:
    """The stats scenario plus a long code, CONFIRMED, with a long description and sources,
    and a cleared fault with an actor and a reason."""
    built = build(tmp_path_factory.mktemp("usability"))
    with FaultLedger.open(built.url, background=False) as ledger:
        at = berlin(22, 5, 40)
        assert ledger.report(LONG, "FAILED", 3, "left arm e-stop pressed by the operator at "
                             "the loading station", "/robot/left_arm/estop_monitor",
                             at=at).accepted
        assert ledger.report(LONG, "FAILED", 3, "again", "/robot/left_arm/second_source",
                             at=at + timedelta(seconds=5)).accepted
        assert ledger.clear("LIDAR_TIMEOUT", actor="cli:alice", reason="cable reseated").success
    return built


def terminal(*args: str, columns: int = 80) -> str:
    code, raw = run_in_terminal(*args, columns=columns)
    text = SGR.sub("", raw.decode("utf-8").replace("\r\n", "\n"))
    assert code == 0, text
    assert "Traceback" not in text
    return text


def widest(text: str) -> int:
    return max(len(line.rstrip()) for line in text.splitlines())


# -- 80 columns ----------------------------------------------------------------------------------
COMMANDS = [
    ("list", "--all"),
    ("show", LONG),
    ("history", "--until", "2026-11-23"),
    ("state-at", "2030-01-01"),
    ("stats", "--since", "2026-11-20/night", "--until", "2026-11-22/morning"),
    ("stats", "--by", "shift", "--group-by", "code", "--since", "2026-11-21/night",
     "--until", "2026-11-21/night"),
    ("report-shift", NIGHT, "--as-of", AS_OF_TEXT),
    ("verify",),
    ("verify", "--since", NIGHT),
]


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: " ".join(c[:2]))
def test_every_table_fits_an_80_column_terminal(scenario: Scenario,
                                                command: tuple[str, ...]) -> None:
    text = terminal(*scenario.cli(*command))
    assert widest(text) <= 80, text
    if command[0] in ("list", "show", "state-at"):
        assert LONG in text, text  # the whole code on one line
        assert "CONFIRMED" in text
        for token in re.findall(r"[A-Z]{2,}", text):  # no status cut into pieces
            pieces = [s for s in STATUSES if token not in (s, "FAILED", "PASSED")
                      and (s.startswith(token) or s.endswith(token))]
            assert not pieces, (token, text)
    if command[0] == "history":  # shortened on one line (its start and end), never split
        assert re.search(r"HW_LEFT_ARM\S*…\S*EMERGENCY_STOP", text), text


def test_list_leaves_out_the_least_important_columns_first(scenario: Scenario) -> None:
    narrow = terminal(*scenario.cli("list", "--all"))
    assert "sources" not in narrow and "description" not in narrow
    assert "status" in narrow and "code" in narrow
    stats = terminal(*scenario.cli("stats", "--since", NIGHT, "--until", NIGHT))
    assert "activations" in stats and "failed" in stats and "stale" not in stats
    roomy = terminal(*scenario.cli("list", "--all"), columns=200)
    assert "sources" in roomy and "description" in roomy
    assert widest(roomy) <= 200


@pytest.mark.parametrize(("command", "headers"), [
    (("list", "--all"), ["sources", "description", "counter"]),
    (("show", LONG), ["sources", "description", "cause"]),
    (("history", "--until", "2026-11-23"), ["kind", "source", "details"]),
    (("state-at", "2030-01-01"), ["sources", "description"]),
    (("stats", "--since", NIGHT, "--until", NIGHT), ["chattering", "stale", "MTTR"]),
    (("report-shift", NIGHT, "--as-of", AS_OF_TEXT), ["change %", "episode", "MTTR"]),
], ids=lambda c: c[0] if isinstance(c, tuple) else "")
def test_wide_shows_every_column(scenario: Scenario, command: tuple[str, ...],
                                 headers: list[str]) -> None:
    text = terminal(*scenario.cli(*command, "--wide"))
    for header in headers:
        assert header in text, (header, text)
    assert LONG in text or command[0] in ("stats", "report-shift")


# -- the time grammar ----------------------------------------------------------------------------
def test_state_at_and_list_at_take_shift_ids_dates_and_calendar_local_times(
        scenario: Scenario) -> None:
    by_id = invoke("state-at", *scenario.cli(NIGHT, "--json"))
    assert by_id.exit_code == 0, by_id.stderr
    local = invoke("state-at", *scenario.cli("2026-11-21T22:00", "--json"))
    utc = invoke("state-at", *scenario.cli("2026-11-21T21:00Z", "--json"))
    assert json.loads(by_id.stdout) == json.loads(local.stdout) == json.loads(utc.stdout)
    listed = invoke("list", *scenario.cli("--at", NIGHT, "--json"))
    assert listed.exit_code == 0, listed.stderr
    codes = {f["fault_code"] for f in json.loads(listed.stdout)}
    assert codes == {f["fault_code"] for f in json.loads(by_id.stdout)["faults"]}


def test_history_and_verify_take_shift_ids(scenario: Scenario) -> None:
    done = invoke("history", *scenario.cli("--since", NIGHT, "--until", NIGHT, "--json"))
    assert done.exit_code == 0, done.stderr
    rows = [json.loads(line) for line in done.stdout.splitlines()]
    with scenario.ledger() as ledger:
        expected = ledger.history(since=berlin(21, 22, 0), until=berlin(22, 6, 0))
    assert [r["seq"] for r in rows] == [r.seq for r in expected] and expected
    checked = invoke("verify", *scenario.cli("--since", NIGHT))  # recorded after it
    assert checked.exit_code == 0, checked.stderr


def test_report_at_is_in_the_calendars_zone(scenario: Scenario, tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'r.db'}"
    done = invoke("report", "X_TEST", "FAILED", "--at", "2026-11-21T23:00", "--db", url,
                  "--shifts", str(scenario.shifts))
    assert done.exit_code == 0, done.stderr
    rows = invoke("history", "--db", url, "--json", "--kind", "fault_reported")
    [row] = [json.loads(line) for line in rows.stdout.splitlines()]
    assert row["occurred_at"].startswith("2026-11-21T22:00:00")  # 23:00 Berlin = 22:00 UTC


@pytest.mark.parametrize(("args", "words"), [
    (("history", "--since", "yesterday"), "--since must be an ISO 8601 date or time"),
    (("history", "--until", "2026-11-21/lunch"), "--until: no shift 'lunch'"),
    (("state-at", "soon"), "WHEN|SEQ must be a seq number or an ISO 8601 date or time"),
    (("verify", "--since", "9999-12-31"), "is outside the times the log can hold"),
    (("report-shift", "--as-of", "1960-01-01"), "is outside the times the log can hold"),
])
def test_bad_times_are_one_line_and_exit_2(scenario: Scenario, args: tuple[str, ...],
                                           words: str) -> None:
    assert_clean_error(invoke(*scenario.cli(*args)), words)


# -- errors, not silence -------------------------------------------------------------------------
def test_an_unknown_status_is_refused(scenario: Scenario) -> None:
    done = invoke("list", *scenario.cli("--status", "CONFIRMD"))
    assert done.exit_code == 2
    assert done.stderr.strip() == ("error: unknown status 'CONFIRMD'; valid statuses: "
                                   "PREFAILED, PREPASSED, CONFIRMED, HEALED, CLEARED")
    lower = invoke("list", *scenario.cli("--status", "confirmed", "--json"))
    assert lower.exit_code == 0, lower.stderr
    assert LONG in {f["fault_code"] for f in json.loads(lower.stdout)}


def test_show_prints_who_cleared_and_why(scenario: Scenario) -> None:
    done = invoke("show", *scenario.cli("LIDAR_TIMEOUT"))
    assert done.exit_code == 0, done.stderr
    assert "by cli:alice: cable reseated" in done.stdout
    data = json.loads(invoke("show", *scenario.cli("LIDAR_TIMEOUT", "--json")).stdout)
    assert data["last_cleared"]["by"] == "cli:alice"
    assert data["last_cleared"]["reason"] == "cable reseated"
    [clear] = [t for t in data["transitions"] if t["to"] == "CLEARED"]
    assert (clear["by"], clear["reason"]) == ("cli:alice", "cable reseated")


def test_version() -> None:
    done = invoke("--version")
    assert done.exit_code == 0
    assert done.stdout.strip() == f"faultledger {version('faultledger')}"


def test_db_takes_a_plain_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "var").mkdir()
    done = invoke("report", "PLAIN_PATH", "FAILED", "-s", "CRITICAL", "--db", "var/f.db")
    assert done.exit_code == 0, done.stderr
    assert (tmp_path / "var" / "f.db").exists()
    listed = invoke("list", "--db", str(tmp_path / "var" / "f.db"), "--json")
    assert [f["fault_code"] for f in json.loads(listed.stdout)] == ["PLAIN_PATH"]


def test_a_missing_driver_names_the_extra() -> None:
    """On a machine without the postgresql extra (the dev tools install psycopg, so the
    child process hides it): one line naming the extra, exit 2, no password."""
    hide = ("import importlib.util as u, sys; real = u.find_spec; "
            "u.find_spec = lambda n, *a: None if n == 'psycopg' else real(n, *a); "
            "from faultledger.cli.main import main; sys.argv[0] = 'faultledger'; main()")
    done = subprocess.run([sys.executable, "-c", hide, "list", "--db",
                           "postgresql://u:secret@db.example/faults"],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 2, done.stderr
    assert "pip install 'faultledger[postgresql]'" in done.stderr
    assert "secret" not in done.stderr and "Traceback" not in done.stderr
    assert done.stderr.strip().count("\n") == 0


# -- the shift report explains itself ------------------------------------------------------------
def test_report_shift_headlines_e_stops_then_activations_of_all_faults(
    scenario: Scenario
) -> None:
    done = invoke("report-shift", *scenario.cli(NIGHT, "--as-of", AS_OF_TEXT))
    assert done.exit_code == 0, done.stderr
    with scenario.ledger() as ledger:
        [row] = ledger.stats("shift", NIGHT, NIGHT, calendar=scenario.calendar, as_of=AS_OF)
    assert 0 < row.estops < row.activations
    assert (f"{row.estops} e-stops, {row.aborted_goals} aborted goals; {row.activations} "
            f"activations of all faults from {row.failed_reports} failed reports"
            ) in " ".join(done.stdout.split())
    assert "e-stop presses" not in done.stdout
    assert "report-shift --glossary" in done.stdout
    assert "MTBF:" not in done.stdout
    explained = invoke("report-shift", *scenario.cli(NIGHT, "--as-of", AS_OF_TEXT,
                                                     "--glossary"))
    for term, _ in GLOSSARY:
        assert f"{term}:" in explained.stdout, term


def test_html_has_the_glossary_and_the_png_its_key_figures(scenario: Scenario) -> None:
    with scenario.ledger() as ledger:
        report = build_report(ledger, scenario.calendar, NIGHT, AS_OF)
    page = shift_html.html(report)
    assert "<h2>Glossary</h2>" in page
    for term, _ in GLOSSARY:
        assert f"<dt>{term}</dt>" in page
    assert report.headline in page
    lines = shift_html.key_figures_lines(report)
    assert lines[0].startswith(f"Shift {NIGHT}:")
    assert lines[1] == report.headline
    assert shift_html.charts_png(report).startswith(b"\x89PNG")


def test_a_duration_longer_than_the_shift_says_why(scenario: Scenario) -> None:
    """The motor stays CONFIRMED, the lidar episode runs 2 h: summed fault time and the
    episodes are explained when they exceed the elapsed shift."""
    with scenario.ledger() as ledger:
        report = build_report(ledger, scenario.calendar, NIGHT, berlin(21, 23, 30))
    elapsed = (berlin(21, 23, 30) - berlin(21, 22, 0)).total_seconds()
    if any(d.seconds > elapsed for d in report.downtimes):
        assert any("episode is longer than the shift" in n for n in report.notes)
