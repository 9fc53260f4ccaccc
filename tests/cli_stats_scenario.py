"""A scripted two-night scenario for the `stats` and `report-shift` CLI tests: e-stop presses,
a lidar timeout, an overheating motor and action goals that end (aborted, canceled,
succeeded) at explicit Europe/Berlin times, on a real SQLite file.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from fnmatch import fnmatchcase
from pathlib import Path
from zoneinfo import ZoneInfo

from typer.testing import CliRunner, Result

from faultledger import FaultLedger, Policy
from faultledger.cli.main import app
from faultledger.domain.shifts import ShiftCalendar
from faultledger.service.config import load_shift_calendar

BERLIN = ZoneInfo("Europe/Berlin")
CALENDAR_YAML = """\
timezone: Europe/Berlin
shifts:
  - {name: morning, start: "06:00", end: "14:00"}
  - {name: afternoon, start: "14:00", end: "22:00"}
  - {name: night, start: "22:00", end: "06:00"}
"""
ARM1, ARM2 = "HW_ARM1_EMERGENCY_STOP", "HW_ARM2_EMERGENCY_STOP"
RESET = "HW_ARM1_EMERGENCY_STOP_RESET"
"""Matches HW_* but not HW_*_EMERGENCY_STOP."""
LIDAR, MOTOR = "LIDAR_TIMEOUT", "MOTOR_OVERHEAT"
GLOB = "HW_*_EMERGENCY_STOP"
PREVIOUS_NIGHT, NIGHT, MORNING = "2026-11-20/night", "2026-11-21/night", "2026-11-22/morning"
HEALING = Policy(healing_enabled=True, healing_threshold=0)
"""One PASSED heals a fault confirmed by one FAILED."""


def berlin(day: int, hour: int, minute: int, second: int = 0) -> datetime:
    """Local Berlin wall-clock time in November 2026 (UTC+1), as aware UTC."""
    return datetime(2026, 11, day, hour, minute, second, tzinfo=BERLIN).astimezone(UTC)


AS_OF = berlin(22, 13, 0)
AS_OF_TEXT = "2026-11-22T13:00"
"""The same moment as typed on the command line (local to the calendar)."""

# (code, FAILED at, PASSED after seconds or None for never, severity, source)
EPISODES: list[tuple[str, datetime, float | None, int, str]] = [
    # the previous night
    (ARM1, berlin(20, 22, 30), 20.0, 3, "/arm1/estop"),
    (ARM1, berlin(21, 2, 0), 40.0, 3, "/arm1/estop"),
    (LIDAR, berlin(21, 3, 0), 600.0, 2, "/sensors/lidar"),
    # the night
    (ARM1, berlin(21, 22, 10), 30.0, 3, "/arm1/estop"),
    (LIDAR, berlin(21, 23, 0), 7200.0, 2, "/sensors/lidar"),
    (ARM1, berlin(21, 23, 30, 15), 45.0, 3, "/arm1/estop"),
    (RESET, berlin(22, 0, 0), 300.0, 1, "/arm1/estop"),
    (ARM1, berlin(22, 1, 2, 3), 120.0, 3, "/arm1/estop"),
    (ARM1, berlin(22, 2, 45), 10.0, 2, "/arm1/estop"),
    (ARM2, berlin(22, 4, 0), 15.0, 3, "/arm2/estop"),
    (MOTOR, berlin(22, 5, 30), None, 2, "/motor"),     # still CONFIRMED at AS_OF
    # the morning
    (ARM1, berlin(22, 6, 0), 40.0, 2, "/arm1/estop"),
]


NAV, PICK = "/nav/navigate_to_pose", "/arm/pick"
# (action, goal id, terminal status, at, action server node)
GOALS: list[tuple[str, str, str, datetime, str]] = [
    (NAV, "prev-1", "ABORTED", berlin(20, 23, 0), "/bt_navigator"),
    (NAV, "prev-2", "SUCCEEDED", berlin(21, 1, 0), "/bt_navigator"),
    (NAV, "night-1", "ABORTED", berlin(21, 22, 40), "/bt_navigator"),
    (NAV, "night-2", "ABORTED", berlin(21, 22, 41, 30), "/bt_navigator"),
    (NAV, "night-3", "ABORTED", berlin(22, 3, 15), "/bt_navigator"),
    (PICK, "night-4", "CANCELED", berlin(22, 4, 5), "/arm_server"),
    (PICK, "night-5", "SUCCEEDED", berlin(22, 4, 20), "/arm_server"),
    (PICK, "morning-1", "ABORTED", berlin(22, 7, 0), "/arm_server"),
]


def goals(since: datetime, until: datetime, status: str = "ABORTED",
          action: str | None = None) -> int:
    """Goal outcomes of the script in [since, until) with that status (and action)."""
    return sum(1 for name, _, end, at, _ in GOALS
               if since <= at < until and end == status and action in (None, name))


def presses(since: datetime, until: datetime, glob: str = "*") -> int:
    """FAILED reports of the script in [since, until) whose code matches ``glob``; each one
    is an activation and a confirmation (every episode is healed before the next)."""
    return sum(1 for code, at, _, _, _ in EPISODES
               if since <= at < until and fnmatchcase(code, glob))


@dataclass(frozen=True)
class Scenario:
    url: str
    shifts: Path
    calendar: ShiftCalendar

    def cli(self, *args: str) -> list[str]:
        """``args`` with this scenario's --db and --shifts."""
        return [*args, "--db", self.url, "--shifts", str(self.shifts)]

    @contextlib.contextmanager
    def ledger(self) -> Iterator[FaultLedger]:
        """A read-only ledger on the scenario's file, for the expected figures."""
        with FaultLedger.open(self.url, create=False, upgrade=False, background=False,
                              calendar=self.calendar) as ledger:
            yield ledger


def build(tmp_path: Path) -> Scenario:
    url = f"sqlite:///{tmp_path / 'faults.db'}"
    shifts = tmp_path / "shifts.yaml"
    shifts.write_text(CALENDAR_YAML, encoding="utf-8")
    with FaultLedger.open(url, policy=HEALING, background=False) as ledger:
        for code, at, held, severity, source in sorted(EPISODES, key=lambda e: e[1]):
            assert ledger.report(code, "FAILED", severity, "", source, at=at).accepted
            if held is not None:
                assert ledger.report(code, "PASSED", 0, "", source,
                                     at=at + timedelta(seconds=held)).accepted
        for action, goal_id, status, at, server in GOALS:
            assert ledger.record_goal_outcome(action, goal_id, status, server, at=at).accepted
        again = ledger.record_goal_outcome(NAV, "night-1", "ABORTED", "/bt_navigator",
                                           at=berlin(21, 22, 50))
        assert again.duplicate  # a republished status: counted once
    return Scenario(url, shifts, load_shift_calendar(shifts))


def invoke(*args: str) -> Result:
    """Run `faultledger ARGS` in this process; stdout and stderr are kept apart."""
    return CliRunner().invoke(app, list(args))


def assert_clean_error(result: Result, *words: str) -> None:
    """Non-zero exit, a message on stderr with ``words``, no traceback, nothing on stdout."""
    assert result.exit_code != 0, result.stdout
    assert isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.stderr
    assert result.stderr.startswith("error:"), result.stderr
    for word in words:
        assert word in result.stderr, result.stderr
    assert result.stdout == ""
