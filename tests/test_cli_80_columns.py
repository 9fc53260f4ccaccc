"""Every table command at 80 columns, as a robotics engineer runs them (issue 17): the real CLI
on a real SQLite file, on an 80-column pseudo-terminal and in a real 80-column tmux pane.

No line is wider than 80 cells, no time is split over two lines, the columns that matter
survive (e-stops and aborted goals in `stats`, kind in `history`), long ids are shortened
(``--wide`` shows them whole), times are in the shift calendar's zone with the zone named,
and piped output carries no trailing padding.
"""

from __future__ import annotations

import itertools
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import NamedTuple

import pytest
from rich.cells import cell_len

from faultledger import FaultLedger
from tests.cli_stats_scenario import (
    AS_OF_TEXT,
    BERLIN,
    MORNING,
    NAV,
    NIGHT,
    PREVIOUS_NIGHT,
    Scenario,
    berlin,
    build,
)
from tests.test_safe_output import SGR, run_in_terminal

CLI = [sys.executable, "-m", "faultledger.cli.main"]
LONG = "HW_LEFT_ARM_SHOULDER_JOINT_EMERGENCY_STOP"
GOAL_UUID = "3f2a9c1e-7b4d-4c2a-9e1f-0a1b2c3d4e5f"
"""A goal id as the action status bridge writes it (a ROS goal UUID)."""
DATE = re.compile(r"\d{4}-\d{2}-\d{2}")
BOX = "│┃"


@pytest.fixture(scope="module")
def scenario(tmp_path_factory: pytest.TempPathFactory) -> Scenario:
    """The two-night Berlin scenario, plus a 41-character e-stop code with a long
    description, a cleared fault and a goal with a UUID id."""
    built = build(tmp_path_factory.mktemp("eighty"))
    with FaultLedger.open(built.url, background=False) as ledger:
        assert ledger.report(LONG, "FAILED", 3, "left arm e-stop pressed by the operator at "
                             "the loading station", "/robot/left_arm/estop_monitor",
                             at=berlin(22, 5, 40)).accepted
        assert ledger.record_goal_outcome(NAV, GOAL_UUID, "ABORTED", "/bt_navigator",
                                          at=berlin(22, 3, 30)).accepted
        assert ledger.clear("LIDAR_TIMEOUT", actor="cli:alice", reason="cable reseated").success
    return built


class Shown(NamedTuple):
    stdout: str
    stderr: str


def run(*args: str, columns: int | None = 80) -> Shown:
    """The real CLI on a pseudo-terminal of ``columns`` columns (stdout and stderr both on
    it, as a person sees them, colours removed); None: stdout piped, stderr apart."""
    if columns is None:
        env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
        done = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=120,
                              env=env)
        assert done.returncode == 0, done.stderr
        assert "Traceback" not in done.stderr
        return Shown(done.stdout, done.stderr)
    code, raw = run_in_terminal(*args, columns=columns)
    text = SGR.sub("", raw.decode("utf-8").replace("\r\n", "\n"))
    assert code == 0, text
    assert "Traceback" not in text
    return Shown(text, "")


def split_times(text: str) -> list[str]:
    """Places where a time was broken over two lines: a date ending its line (or its cell)
    with a clock time under it on the next line, or a clock time cut short."""
    found: list[str] = []
    lines = text.splitlines()
    for i, line in enumerate(lines):
        found += re.findall(r"\d{2}:\d{2}:\d(?!\d)|\d{2}:\d(?![\d:])", line)
        for match in DATE.finditer(line):
            rest = line[match.end():]
            if rest.strip() and rest.lstrip()[0] not in BOX:
                continue
            below = lines[i + 1][match.start():] if i + 1 < len(lines) else ""
            if re.match(r"\s*\d{2}:\d{2}", below):
                found.append(f"{line!r} / {lines[i + 1]!r}")
    return found


def assert_fits(text: str, width: int = 80) -> None:
    wide = [line for line in text.splitlines() if cell_len(line) > width]
    assert not wide, "\n".join(wide)
    assert not split_times(text), split_times(text)


def local(moment: datetime) -> str:
    """How a time of the Berlin scenario is shown: the calendar's wall clock."""
    return f"{moment.astimezone(BERLIN):%Y-%m-%d %H:%M:%S}"


COMMANDS = [
    ("list", "--all"),
    ("list", "--at", "2030-01-01"),
    ("show", LONG),
    ("show", "LIDAR_TIMEOUT"),
    ("history",),
    ("history", "--kind", "goal_outcome"),
    ("state-at", "2030-01-01"),
    ("stats", "--by", "shift", "--code", "HW_*_EMERGENCY_STOP", "--since", PREVIOUS_NIGHT,
     "--until", MORNING, "--as-of", AS_OF_TEXT),
    ("stats", "--by", "hour", "--since", NIGHT, "--until", NIGHT, "--as-of", AS_OF_TEXT),
    ("stats", "--by", "day", "--since", "2026-11-20", "--until", "2026-11-23",
     "--as-of", AS_OF_TEXT),
    ("stats", "--group-by", "code", "--since", NIGHT, "--until", NIGHT, "--as-of", AS_OF_TEXT),
    ("stats", "--group-by", "action", "--since", NIGHT, "--until", NIGHT,
     "--as-of", AS_OF_TEXT),
    ("report-shift", NIGHT, "--as-of", AS_OF_TEXT),
]


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: " ".join(c[:3]))
def test_every_table_fits_80_columns_and_no_time_is_split(scenario: Scenario,
                                                          command: tuple[str, ...]) -> None:
    done = run(*scenario.cli(*command))
    assert_fits(done.stdout)
    assert_fits(done.stderr)


def test_the_headline_query_keeps_e_stops_and_aborted_goals(scenario: Scenario) -> None:
    """README: `stats --by shift --code 'HW_*_EMERGENCY_STOP'`: e-stops per shift."""
    out = run(*scenario.cli("stats", "--by", "shift", "--code", "HW_*_EMERGENCY_STOP",
                            "--since", PREVIOUS_NIGHT, "--until", MORNING,
                            "--as-of", AS_OF_TEXT)).stdout
    header = next(line for line in out.splitlines() if line.startswith("┃"))
    assert [c.strip() for c in header.split("┃")[1:-1]][:3] == [
        "period", "e-stops", "aborted goals"]
    with scenario.ledger() as ledger:
        rows = ledger.stats("shift", PREVIOUS_NIGHT, MORNING, ["HW_*_EMERGENCY_STOP"],
                            calendar=scenario.calendar, as_of=berlin(22, 13, 0))
    shown = {c[0]: c for c in ([p.strip() for p in line.split("│")[1:-1]]
                               for line in out.splitlines() if line.startswith("│"))}
    for row in rows:
        assert shown[row.period.id][1:3] == [str(row.estops), str(row.aborted_goals)]
    assert shown[NIGHT][1:3] == ["6", "4"]  # 6 presses; 3 aborted goals + the UUID one
    wide = run(*scenario.cli("stats", "--by", "shift", "--since", NIGHT, "--until", NIGHT,
                             "--as-of", AS_OF_TEXT), columns=None).stdout
    assert "2026-11-21 22:00–2026-11-22 06:00" in wide  # room: the local time, whole
    assert "local time (Europe/Berlin)" in wide


def test_history_keeps_kind_and_local_times_and_shortens_long_ids(
        scenario: Scenario) -> None:
    out = run(*scenario.cli("history")).stdout
    assert "kind" in out and "(Europe/Berlin)" in out
    assert out.count("fault_reported") >= 20 and "goal_outcome" in out
    assert "fault_cleared" in out
    with scenario.ledger() as ledger:
        records = ledger.history()
    for record in records:  # every occurred time on one line, in Berlin time
        assert local(record.occurred_at) in out, local(record.occurred_at)
    assert "2026-11-21 21:10:00" not in out  # 22:10 Berlin is 21:10 UTC: not shown as UTC
    assert re.search(r"HW_LEFT_ARM\S*…\S*EMERGENCY_STOP", out)  # shortened, one line
    assert "ABORTED goal 3f2a9c1e…" in out and GOAL_UUID not in out
    goal_rows = [line for line in out.splitlines() if "/nav/navigate_to_pose" in line]
    assert goal_rows  # the action, on the line of its row's seq
    wide = run(*scenario.cli("history", "--wide")).stdout
    assert LONG in wide and GOAL_UUID in wide


def test_times_everywhere_are_in_the_calendar_zone_and_json_keeps_offsets(
        scenario: Scenario) -> None:
    show = run(*scenario.cli("show", "LIDAR_TIMEOUT", "--wide")).stdout
    assert "at (Europe/Berlin)" in show and local(berlin(21, 23, 0)) + ".000" in show
    assert re.search(r"last cleared \d{4}-\d{2}-\d{2} \d{2}:\d{2}:\d{2} Europe/Berlin by "
                     r"cli:alice: cable reseated", show)
    listed = run(*scenario.cli("list", "--all", "--wide")).stdout
    assert "last occurred (Europe/Berlin)" in listed
    assert local(berlin(22, 5, 40)) + ".000" in listed
    as_json = run(*scenario.cli("list", "--all", "--json")).stdout
    assert '"last_occurred": "2026-11-22T04:40:00.000+00:00"' in as_json  # machine: UTC ISO
    report = run(*scenario.cli("report-shift", NIGHT, "--as-of", AS_OF_TEXT)).stdout
    assert "confirmed at" in report and "(Europe/Berlin)" in report
    assert "23:00:00" in report  # the lidar episode, Berlin time, within the shift


def test_utc_calendar_names_utc(scenario: Scenario) -> None:
    out = run("history", "--db", scenario.url, "--kind", "fault_cleared").stdout
    assert "(UTC)" in out


def test_a_repeated_wall_clock_hour_says_which_one(tmp_path: Path) -> None:
    """02:30 happens twice in Berlin on 2026-10-25: the abbreviation tells them apart."""
    url = f"sqlite:///{tmp_path / 'dst.db'}"
    first = datetime(2026, 10, 25, 0, 30, tzinfo=UTC)  # 02:30 CEST
    with FaultLedger.open(url, background=False) as ledger:
        ledger.report("DST_A", "FAILED", 2, "", "/x", at=first)
        ledger.report("DST_B", "FAILED", 2, "", "/x", at=first + timedelta(hours=1))  # CET
    shifts = tmp_path / "shifts.yaml"
    shifts.write_text("timezone: Europe/Berlin\nshifts:\n"
                      "  - {name: day, start: '06:00', end: '18:00'}\n", encoding="utf-8")
    out = run("history", "--db", url, "--shifts", str(shifts)).stdout
    assert "2026-10-25 02:30:00 CEST" in out and "2026-10-25 02:30:00 CET" in out


def test_piped_tables_carry_no_padding(scenario: Scenario) -> None:
    for command in (("list", "--all"), ("history",), ("stats", "--since", NIGHT, "--until",
                                                      NIGHT, "--as-of", AS_OF_TEXT),
                    ("report-shift", NIGHT, "--as-of", AS_OF_TEXT)):
        out = run(*scenario.cli(*command), columns=None).stdout
        padded = [line for line in out.splitlines() if line != line.rstrip()]
        assert not padded, padded[:3]
        assert max(cell_len(line) for line in out.splitlines()) <= 200


def test_wide_shows_every_column(scenario: Scenario) -> None:
    stats = run(*scenario.cli("stats", "--since", NIGHT, "--until", NIGHT,
                              "--as-of", AS_OF_TEXT, "--wide")).stdout
    for header in ("e-stops", "aborted goals", "activations", "failed", "confirmations",
                   "MTTR", "flood %", "chattering", "stale", "local time (Europe/Berlin)"):
        assert header in stats, header


# -- --help --------------------------------------------------------------------------------------
HELP = [(), ("list",), ("show",), ("history",), ("verify",), ("state-at",), ("stats",),
        ("report-shift",), ("demo",), ("report",), ("anchor",), ("db",), ("token", "create"),
        ("policy",), ("policy", "explain")]


@pytest.mark.parametrize("command", HELP, ids=lambda c: " ".join(c) or "faultledger")
def test_help_is_reflowed_and_flags_show_no_type(command: tuple[str, ...]) -> None:
    text = run(*command, "--help").stdout
    assert_fits(text)
    assert "<bool>" not in text, text
    options = [line for line in text.splitlines() if line.startswith("  -")]
    for noise in ("<str>", "<list[", "<path>", "<int"):  # options name what they take
        assert not [line for line in options if noise in line], (noise, text)
    # Paragraphs are filled: a line ends early only where its paragraph or entry ends.
    lines = text.splitlines()
    for line, following in itertools.pairwise(lines):
        if not line.strip() or not following.strip() or following.startswith("  -"):
            continue
        if line.startswith("  ") and not line.startswith("   ") and "  " in line.strip():
            continue  # an option's or command's first line ends where its words allow
        indent = len(following) - len(following.lstrip())
        if indent != len(line) - len(line.lstrip()):
            continue  # the next entry
        assert len(line.rstrip()) + 2 + len(following.split()[0]) > 78, (line, following)


def test_command_list_descriptions_are_one_line_each() -> None:
    text = run("--help").stdout
    commands = text[text.index("Commands:"):].splitlines()[1:]
    assert all(re.match(r"  [a-z-]+ +\S", line) for line in commands if line.strip()), text
    assert not any(line.rstrip().endswith("...") for line in commands), text


# -- a real terminal -----------------------------------------------------------------------------
@pytest.mark.skipif(shutil.which("tmux") is None, reason="needs tmux")
@pytest.mark.parametrize("command", [
    ("stats", "--by", "shift", "--code", "HW_*_EMERGENCY_STOP", "--since", PREVIOUS_NIGHT,
     "--until", MORNING, "--as-of", AS_OF_TEXT),
    ("history", "--from-seq", "20"),
    ("report-shift", NIGHT, "--as-of", AS_OF_TEXT),
    ("list", "--at", "2026-11-21/night"),
], ids=lambda c: c[0])
def test_in_an_80_column_tmux_pane(scenario: Scenario, tmp_path: Path,
                                   command: tuple[str, ...]) -> None:
    """What a person sees: the screen of a real 80x60 terminal (stderr's notes included)."""
    screen = tmux_screen(scenario.cli(*command), tmp_path)
    assert_fits(screen)
    if command[0] == "stats":
        assert "e-stops" in screen and "aborted goals" in screen
    if command[0] == "history":
        assert "kind" in screen and "goal_outcome" in screen and "(Europe/Berlin)" in screen
    if command[0] == "report-shift":
        assert "confirmed at" in screen and "e-stops" in screen
    if command[0] == "list":  # records recorded later that occurred before the night
        assert "note: the table is by recording time" in screen
        assert "2026-11-21 22:00:00 Europe/Berlin" in screen  # never split by the wrapping


def tmux_screen(args: list[str], tmp_path: Path, width: int = 80) -> str:
    socket = f"faultledger-test-{os.getpid()}-{time.monotonic_ns()}"
    tmux = ["tmux", "-L", socket, "-f", "/dev/null"]
    done_file = tmp_path / "done"
    command = " ".join(shlex.quote(a) for a in [*CLI, *args])
    command += f"; touch {shlex.quote(str(done_file))}; sleep 60"
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    subprocess.run([*tmux, "new-session", "-d", "-x", str(width), "-y", "60", command],
                   check=True, timeout=10, env=env)
    try:
        deadline = time.monotonic() + 60
        while not done_file.exists():
            assert time.monotonic() < deadline, "the CLI did not finish in 60 s"
            time.sleep(0.1)
        return subprocess.run([*tmux, "capture-pane", "-p", "-S", "-", "-t", "0"],
                              capture_output=True, text=True, timeout=10, check=True).stdout
    finally:
        subprocess.run([*tmux, "kill-server"], capture_output=True, timeout=10)
