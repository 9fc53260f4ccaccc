"""``~/get_statistics`` against a real fault manager process (SPEC §7, §8; docs/ros.md).

The database is filled through the Python API with explicit stamps before the manager starts
(ROS reports carry no stamp: they would be timed by their arrival). Every answer is compared,
row by row and figure by figure, with ``FaultLedger.stats`` on the same file, read by a second,
read-only ledger while the manager serves it. ``as_of`` is always given where open episodes
matter, so both sides end them at the same moment.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, fields
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
from builtin_interfaces.msg import Time
from faultledger_msgs.msg import StatsRow as StatsRowMsg
from faultledger_msgs.srv import GetStatistics

from faultledger import FaultLedger, Policy
from faultledger.domain.clock import to_ns
from faultledger.domain.stat_rows import StatsRow
from faultledger.errors import InvalidInputError
from faultledger.service.config import load_shift_calendar

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

NS = "/fault_manager"
SERVICE = f"{NS}/get_statistics"
HEALING = Policy(healing_enabled=True, healing_threshold=0)
"""One PASSED heals a fault confirmed by one FAILED; the manager runs with the same policy."""
HEALING_ARGS = ("--ros-args", "-p", "healing_enabled:=true", "-p", "healing_threshold:=0")
AS_OF = datetime(2026, 11, 21, 12, 0, 30, 500_000, tzinfo=UTC)
"""Default range with this as_of: [2026-11-20T12:00, 2026-11-21T12:00) UTC."""
ESTOP_GLOB = "HW_*_EMERGENCY_STOP"
FIGURES = tuple(f.name for f in fields(StatsRow)
                if f.name not in ("period", "group", "complete"))  # complete: a central's
PERIOD_FIELDS = ("period_id", "period_name", "production_day", "start", "end")
GROUP_FIELDS = ("code", "source", "severity", "action")
BERLIN_SHIFTS = """\
timezone: Europe/Berlin
shifts:
  - {name: early, start: "05:30", end: "13:30"}
  - {name: late, start: "13:30", end: "21:30", weekdays: [mon, tue, wed, thu, fri]}
"""


def utc(day: int, hour: int, minute: int = 0, second: int = 0, micro: int = 0) -> datetime:
    return datetime(2026, 11, day, hour, minute, second, micro, tzinfo=UTC)


def stamp(moment: datetime) -> Any:
    seconds, nanoseconds = divmod(to_ns(moment), 1_000_000_000)
    return Time(sec=seconds, nanosec=nanoseconds)


# -- the scenario ----------------------------------------------------------------------------------
def press(ledger: FaultLedger, code: str, source: str, at: datetime, held: float,
          severity: int) -> None:
    """FAILED (confirms: threshold -1) and, ``held`` seconds later, PASSED (heals)."""
    assert ledger.report(code, "FAILED", severity, "pressed", source, at=at).accepted
    assert ledger.report(code, "PASSED", 0, "", source, at=at + timedelta(seconds=held)).accepted


def fill(ledger: FaultLedger) -> None:
    """Three days of an arm cell: e-stops, a flooding action, a stale lidar, a cleared motor."""
    # Stale: confirmed the day before the default range and never released.
    assert ledger.report("LIDAR_TIMEOUT", "FAILED", 2, "no scan", "/lidar/front",
                         at=utc(19, 10, 0, 0, 123_456)).accepted
    # E-stops on two arms; the three presses within 50 s chatter.
    for at, held, severity in [(utc(19, 15, 5), 30.0, 3), (utc(20, 13, 59, 59, 999_999), 20.0, 3),
                               (utc(20, 14, 0), 5.0, 2), (utc(20, 21, 59, 50), 15.0, 3),
                               (utc(20, 22, 0, 10), 5.0, 3), (utc(20, 22, 0, 40), 5.0, 3),
                               (utc(21, 1, 2, 3, 250_000), 120.0, 3)]:
        press(ledger, "HW_ARM1_EMERGENCY_STOP", "/arm1/estop", at, held, severity)
    for at, held in [(utc(20, 16, 30), 300.0), (utc(21, 7, 45, 30), 42.5)]:
        press(ledger, "HW_ARM2_EMERGENCY_STOP", "/arm2/estop", at, held, 2)
    # Not selected by the glob.
    press(ledger, "HW_ARM1_EMERGENCY_STOP_RESET", "/arm1/estop", utc(20, 18, 0), 1.0, 1)
    # Flood: 12 confirmations within the 10-minute window 23:00-23:10.
    for k in range(12):
        press(ledger, "ACTION_NAV_ABORTED", "/nav/bt", utc(20, 23) + timedelta(seconds=40 * k),
              10.0, 1)
    # Two sources with different severities, then an operator's clear (a repair by clear).
    assert ledger.report("MOTOR_OVERHEAT", "FAILED", 1, "warm", "/motor/left",
                         at=utc(21, 3, 0)).accepted
    assert ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "hot", "/motor/right",
                         at=utc(21, 3, 20)).accepted
    assert ledger.clear("MOTOR_OVERHEAT", actor="cli:alice", at=utc(21, 4, 15)).success
    # Goal outcomes of two actions (what the action-status bridge records), one a duplicate.
    outcomes = [("/nav/navigate_to_pose", "ABORTED", utc(20, 22, 30)),
                ("/nav/navigate_to_pose", "ABORTED", utc(20, 23, 5)),
                ("/nav/navigate_to_pose", "SUCCEEDED", utc(20, 23, 7, 30, 250_000)),
                ("/arm/follow_joint_trajectory", "CANCELED", utc(21, 6, 1)),
                ("/arm/follow_joint_trajectory", "SUCCEEDED", utc(21, 9, 0))]
    for n, (action, status, at) in enumerate(outcomes):
        server = "/nav/bt" if action.startswith("/nav/") else "/arm/controller"
        assert ledger.record_goal_outcome(action, f"goal-{n}", status, server, at=at).accepted
    assert ledger.record_goal_outcome("/nav/navigate_to_pose", "goal-0", "ABORTED", "/nav/bt",
                                      at=utc(21, 10)).duplicate
    # Still CONFIRMED at as_of: an open episode.
    assert ledger.report("HW_ARM2_EMERGENCY_STOP", "FAILED", 3, "", "/arm2/estop",
                         at=utc(21, 11, 30)).accepted


def wait_answering(client: RosClient, timeout: float = 30.0) -> None:
    """Probe ~/get_statistics with short calls until one is answered.

    ``wait_for_service`` only proves that the request reader is matched; an answer sent before
    the server has matched this client's response reader is lost. A first call that times out
    here is re-sent instead of failing a test after 10 s.
    """
    deadline = time.monotonic() + timeout
    probe = GetStatistics.Request(by="bad")  # refused at once, reads nothing
    while True:
        try:
            client.call(GetStatistics, SERVICE, probe, timeout=2.0)
            return
        except AssertionError:  # conftest's ServiceTimeout (imported by pytest as `conftest`)
            if time.monotonic() >= deadline:
                raise


@dataclass
class Served:
    client: RosClient
    ledger: FaultLedger
    """A second, read-only ledger on the manager's database: the expected answers."""
    db_path: Path

    def call(self, request: Any) -> Any:
        return self.client.call(GetStatistics, SERVICE, request)


@pytest.fixture(scope="class")
def served(shared_manager: ManagerFactory, shared_client: RosClient,
           tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    db_path = tmp_path_factory.mktemp("statistics") / "stats.db"
    url = f"sqlite:///{db_path}"
    with FaultLedger.open(url, policy=HEALING, background=False) as writer:
        fill(writer)
    shared_manager(*HEALING_ARGS, db=db_path)
    wait_answering(shared_client)
    with FaultLedger.open(url, upgrade=False, create=False) as reader:
        yield Served(shared_client, reader, db_path)


# -- comparison ------------------------------------------------------------------------------------
def expected_row(row: StatsRow) -> dict[str, Any]:
    """A StatsRow as the message should carry it (undefined figures: NaN)."""
    period = row.period
    return {
        "period_id": period.id,
        "period_name": period.name,
        "production_day": "" if period.production_day is None
        else period.production_day.isoformat(),
        "start": to_ns(period.start),
        "end": to_ns(period.end),
        "code": row.group.get("code", ""),
        "source": row.group.get("source", ""),
        "severity": row.group.get("severity", -1),
        "action": row.group.get("action", ""),
        **{name: math.nan if getattr(row, name) is None else getattr(row, name)
           for name in FIGURES},
    }


def received_row(msg: Any) -> dict[str, Any]:
    values = {name: getattr(msg, name) for name in (*PERIOD_FIELDS, *GROUP_FIELDS, *FIGURES)}
    values["start"] = int(msg.start.sec) * 1_000_000_000 + int(msg.start.nanosec)
    values["end"] = int(msg.end.sec) * 1_000_000_000 + int(msg.end.nanosec)
    return values


def comparable(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """NaN != NaN: replace it by a marker so that whole rows compare with ==."""
    return [{k: "NaN" if isinstance(v, float) and math.isnan(v) else v for k, v in row.items()}
            for row in rows]


def assert_same_rows(response: Any, expected: list[StatsRow]) -> None:
    assert (response.success, response.message) == (True, "")
    got = comparable([received_row(m) for m in response.rows])
    want = comparable([expected_row(r) for r in expected])
    assert len(got) == len(want)
    for index, (g, w) in enumerate(zip(got, want, strict=True)):
        assert g == w, f"row {index} ({w['period_id']} {w['code']!r} {w['source']!r})"


def test_the_message_carries_every_figure_of_stats_row() -> None:
    message_fields = set(StatsRowMsg.get_fields_and_field_types())
    assert message_fields == {*PERIOD_FIELDS, *GROUP_FIELDS, *FIGURES}
    assert StatsRowMsg().severity == -1
    assert GetStatistics.Request().by == ""


class TestStatisticsService:
    """One manager on the prefilled database and one client for the class."""

    def test_service_is_advertised(self, served: Served) -> None:
        node = served.client.node
        assert served.client.spin_until(
            lambda: dict(node.get_service_names_and_types()).get(SERVICE)
            == ["faultledger_msgs/srv/GetStatistics"], 20.0)

    def test_default_request_is_shifts_over_the_24_hours_before_as_of(
            self, served: Served) -> None:
        response = served.call(GetStatistics.Request(as_of=stamp(AS_OF)))
        expected = served.ledger.stats(as_of=AS_OF)
        assert [r.period.id for r in expected] == [
            "2026-11-20/morning", "2026-11-20/afternoon", "2026-11-20/night",
            "2026-11-21/morning"]
        assert_same_rows(response, expected)
        # The scenario exercises what the comparison must carry: NaN and real ratios, KPIs.
        assert any(r.mttr_seconds is None for r in expected)
        assert any(r.mttr_seconds is not None for r in expected)
        night = expected[2]
        assert night.flood_windows == 1 and night.chattering_codes >= 1
        assert all(r.stale_codes >= 1 for r in expected)
        assert math.isnan(response.rows[0].top10_share) == (expected[0].top10_share is None)

    def test_by_hour_with_a_codes_glob_and_time_bounds(self, served: Served) -> None:
        since, until = utc(20, 13, 30, 15, 250_000), utc(21, 2, 0)
        response = served.call(GetStatistics.Request(
            by="hour", since_time=stamp(since), until_time=stamp(until), codes=[ESTOP_GLOB],
            as_of=stamp(AS_OF)))
        expected = served.ledger.stats(by="hour", since=since, until=until, codes=[ESTOP_GLOB],
                                       as_of=AS_OF)
        assert len(expected) == 13
        assert expected[0].period.start == since  # cropped to the bound, to the microsecond
        assert sum(r.activations for r in expected) == 7
        assert_same_rows(response, expected)

    @pytest.mark.parametrize(("by", "since", "until", "group_by"), [
        ("day", "2026-11-19", "2026-11-21T12:00", ["code"]),
        ("shift", "2026-11-20/night", "2026-11-21/morning", ["code", "source", "severity"]),
        ("10min", "2026-11-19T00:00", "2026-11-21T12:00", []),
        ("10min", "2026-11-20T22:00", "2026-11-21T00:00", ["severity"]),
        ("shift", "2026-11-20/night", "2026-11-21/morning", ["action", "source"]),
        ("day", "2026-11-20", "2026-11-22", ["action"]),
    ])
    def test_string_bounds_and_group_by(self, served: Served, by: str, since: str, until: str,
                                        group_by: list[str]) -> None:
        response = served.call(GetStatistics.Request(
            by=by, since=since, until=until, group_by=group_by, as_of=stamp(AS_OF)))
        expected = served.ledger.stats(by=by, since=since, until=until, group_by=group_by,
                                       as_of=AS_OF)
        assert expected
        assert_same_rows(response, expected)
        if "code" in group_by:
            assert {m.code for m in response.rows} >= {
                "LIDAR_TIMEOUT", "HW_ARM1_EMERGENCY_STOP", "ACTION_NAV_ABORTED",
                "MOTOR_OVERHEAT"}
        if "source" in group_by and "action" not in group_by:
            assert {m.source for m in response.rows} >= {"/motor/left", "/motor/right",
                                                           "cli:alice"}
        if {"source", "action"} <= set(group_by):
            assert {m.source for m in response.rows} == {"/nav/bt", "/arm/controller"}
        if not group_by:
            assert all((m.code, m.source, m.severity, m.action) == ("", "", -1, "")
                       for m in response.rows)
        if "action" in group_by:
            assert {m.action for m in response.rows} == {
                "/nav/navigate_to_pose", "/arm/follow_joint_trajectory"}
            nav = [m for m in response.rows if m.action == "/nav/navigate_to_pose"]
            assert (sum(m.aborted_goals for m in nav), sum(m.succeeded_goals for m in nav),
                    sum(m.canceled_goals for m in nav)) == (2, 1, 0)
            assert all(m.failed_reports == 0 and m.code == "" for m in response.rows)

    def test_mixed_string_and_time_bounds(self, served: Served) -> None:
        until = utc(21, 0, 0)
        response = served.call(GetStatistics.Request(
            by="hour", since="2026-11-20T20:00", until_time=stamp(until),
            codes=["ACTION_*", "MOTOR_*"], group_by=["code"], as_of=stamp(AS_OF)))
        expected = served.ledger.stats(by="hour", since="2026-11-20T20:00", until=until,
                                       codes=["ACTION_*", "MOTOR_*"], group_by=["code"],
                                       as_of=AS_OF)
        assert [r.group for r in expected] == [{"code": "ACTION_NAV_ABORTED"}]
        assert_same_rows(response, expected)

    def test_empty_request_ends_now(self, served: Served) -> None:
        before = time.time_ns()
        response = served.call(GetStatistics.Request())
        assert (response.success, response.message) == (True, "")
        end = int(response.rows[-1].end.sec) * 1_000_000_000 + int(response.rows[-1].end.nanosec)
        first = response.rows[0].start
        start = int(first.sec) * 1_000_000_000 + int(first.nanosec)
        assert before <= end <= time.time_ns() + 1_000  # until defaults to now, to the microsecond
        assert end - start == 24 * 3600 * 10**9
        assert {m.period_name for m in response.rows} <= {
            "morning", "afternoon", "night", "unscheduled"}

    # -- refused requests -----------------------------------------------------------------------
    @pytest.mark.parametrize("arguments", [
        {"by": "week"},
        {"since": "yesterday"},
        {"until": "2026-11-20/graveyard"},
        {"since": "2026-11-21", "until": "2026-11-20"},
        {"group_by": ["code", "code"]},
        {"group_by": ["fault_code"]},
        {"codes": [""]},
    ], ids=["by", "since", "shift-id", "reversed", "group-twice", "group-unknown", "empty-glob"])
    def test_bad_input_is_refused_with_the_ledgers_message(
            self, served: Served, arguments: dict[str, Any]) -> None:
        with pytest.raises(InvalidInputError) as raised:
            served.ledger.stats(as_of=AS_OF, **arguments)
        response = served.call(GetStatistics.Request(as_of=stamp(AS_OF), **arguments))
        assert (response.success, response.message, list(response.rows)) == (
            False, str(raised.value), [])
        assert response.message
        self.assert_still_serving(served)

    @pytest.mark.parametrize(("fields_", "message"), [
        ({"since": "2026-11-20", "since_time": stamp(utc(20, 0))},
         "give since or since_time, not both"),
        ({"until": "2026-11-21", "until_time": stamp(utc(21, 0))},
         "give until or until_time, not both"),
        ({"until_time": Time(sec=1_795_000_000, nanosec=1)},
         "until_time must be a whole number of microseconds (nanosec % 1000 == 0), got "
         "sec=1795000000 nanosec=1"),
        ({"as_of": Time(sec=1_795_000_000, nanosec=999_999_999)},
         "as_of must be a whole number of microseconds (nanosec % 1000 == 0), got "
         "sec=1795000000 nanosec=999999999"),
    ], ids=["since-twice", "until-twice", "sub-microsecond-until", "sub-microsecond-as-of"])
    def test_ambiguous_or_inexact_bounds_are_refused(
            self, served: Served, fields_: dict[str, Any], message: str) -> None:
        request = GetStatistics.Request(**fields_)
        if "as_of" not in fields_:
            request.as_of = stamp(AS_OF)
        response = served.call(request)
        assert (response.success, response.message, list(response.rows)) == (
            False, message, [])
        self.assert_still_serving(served)

    @staticmethod
    def assert_still_serving(served: Served) -> None:
        response = served.call(GetStatistics.Request(
            by="day", since="2026-11-20", until="2026-11-21", as_of=stamp(AS_OF)))
        assert_same_rows(response, served.ledger.stats(
            by="day", since="2026-11-20", until="2026-11-21", as_of=AS_OF))


# -- the configured shift calendar -----------------------------------------------------------------
def test_serve_uses_the_configured_shift_calendar(
        manager: ManagerFactory, client: RosClient, tmp_path: Path) -> None:
    shifts = tmp_path / "shifts.yaml"
    shifts.write_text(BERLIN_SHIFTS, encoding="utf-8")
    config = tmp_path / "faultledger.yaml"
    config.write_text(f"shifts: {shifts}\n"
                      "policy: {healing_enabled: true, healing_threshold: 0}\n", encoding="utf-8")
    db_path = tmp_path / "calendar.db"
    url = f"sqlite:///{db_path}"
    with FaultLedger.open(url, policy=HEALING, background=False) as writer:
        fill(writer)
    manager("--config", str(config), db=db_path)
    wait_answering(client)
    calendar = load_shift_calendar(shifts)
    since, until = "2026-11-20", "2026-11-22"  # Friday and Saturday (no late shift)
    response = client.call(GetStatistics, SERVICE, GetStatistics.Request(
        since=since, until=until, group_by=["code"], as_of=stamp(AS_OF)))
    with FaultLedger.open(url, upgrade=False, create=False) as reader:
        expected = reader.stats(since=since, until=until, group_by=["code"], calendar=calendar,
                                as_of=AS_OF)
    assert_same_rows(response, expected)
    assert {r.period_name for r in response.rows} == {"early", "late", "unscheduled"}
    assert "2026-11-21/late" not in {r.period_id for r in response.rows}
    # The shift ids of the configured calendar are bounds, too.
    response = client.call(GetStatistics, SERVICE, GetStatistics.Request(
        since="2026-11-20/late", until="2026-11-20/late", as_of=stamp(AS_OF)))
    assert [(r.period_id, r.production_day) for r in response.rows] == [
        ("2026-11-20/late", "2026-11-20")]


def test_a_bad_shift_calendar_stops_the_manager_before_it_serves(tmp_path: Path) -> None:
    shifts = tmp_path / "shifts.yaml"
    shifts.write_text("timezone: Mars/Olympus\nshifts: [{name: early, start: '06:00', "
                      "end: '14:00'}]\n", encoding="utf-8")
    config = tmp_path / "faultledger.yaml"
    config.write_text(f"shifts: {shifts}\n", encoding="utf-8")
    result = subprocess.run(
        [sys.executable, "-m", "faultledger.cli.main", "serve", "--db",
         f"sqlite:///{tmp_path / 'faults.db'}", "--config", str(config)],
        stdin=subprocess.DEVNULL, capture_output=True, text=True, cwd=tmp_path, timeout=60,
        check=False)
    assert result.returncode != 0
    assert "fault_manager ready" not in result.stdout
    assert f"shift calendar {shifts} is invalid" in result.stderr
    assert "unknown IANA time zone 'Mars/Olympus'" in result.stderr
