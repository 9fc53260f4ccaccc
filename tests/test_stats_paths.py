"""Statistics: the per-minute path equals the per-fact path (also with a partial first and
last minute), periods, bounds, bad input, goal outcomes and `group_by` action, ranges with no
end (they end now), and the first open after the upgrades that added the statistics and the
goal tables."""

from __future__ import annotations

import contextlib
import json
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from alembic import command
from alembic.config import Config
from sqlalchemy import create_engine

from faultledger import FaultLedger, Policy, ShiftCalendar, StatsRow
from faultledger.domain.periods import default_calendar, parse_bound, periods
from faultledger.errors import InvalidInputError

MIGRATIONS = Path(__file__).resolve().parents[1] / "src" / "faultledger" / "migrations"
T0 = datetime(2026, 11, 20, 6, 0, tzinfo=UTC)
HEALING = Policy(confirmation_threshold=-1, healing_enabled=True, healing_threshold=0)
BERLIN = ShiftCalendar.model_validate({"timezone": "Europe/Berlin", "shifts": [
    {"name": "morning", "start": "06:00", "end": "14:00"},
    {"name": "afternoon", "start": "14:00", "end": "22:00"},
    {"name": "night", "start": "22:00", "end": "06:00"},
]})


def url(path: Path) -> str:
    return f"sqlite:///{path}"


def busy_log(ledger: FaultLedger) -> None:
    """A flood (12 confirmations in 5 minutes), a chattering code, a fault CONFIRMED for
    two days, a clear, and one still open at the end."""
    for i in range(12):
        at = T0 + timedelta(minutes=1, seconds=20 * i)
        ledger.report(f"FLOOD_{i:02d}", "FAILED", severity=2, source_id="/cell", at=at)
        ledger.report(f"FLOOD_{i:02d}", "PASSED", source_id="/cell", at=at + timedelta(seconds=7))
    for i in range(4):
        at = T0 + timedelta(hours=3, seconds=15 * i)
        ledger.report("GRIPPER_CHATTER", "FAILED", severity=1, source_id="/gripper", at=at)
        ledger.report("GRIPPER_CHATTER", "PASSED", source_id="/gripper",
                      at=at + timedelta(seconds=5))
    ledger.report("LIDAR_DIRTY", "FAILED", severity=1, source_id="/lidar",
                  at=T0 - timedelta(hours=30))
    ledger.report("LIDAR_DIRTY", "PASSED", source_id="/lidar", at=T0 + timedelta(hours=20))
    ledger.report("ESTOP", "FAILED", severity=3, source_id="/safety",
                  at=T0 + timedelta(hours=5, minutes=30, seconds=10))
    ledger.clear("ESTOP", actor="cli:alice", at=T0 + timedelta(hours=6))
    ledger.report("MOTOR_HOT", "FAILED", severity=2, source_id="/motor",
                  at=T0 + timedelta(hours=9, seconds=1))


@pytest.fixture
def ledger(tmp_path: Path) -> FaultLedger:
    opened = FaultLedger.open(url(tmp_path / "faults.db"), policy=HEALING, background=False)
    busy_log(opened)
    return opened


@pytest.mark.parametrize("by", ["shift", "day", "hour", "10min"])
def test_minute_path_equals_fact_path(ledger: FaultLedger, by: str) -> None:
    since, until = T0 - timedelta(days=1), T0 + timedelta(days=1, hours=2)
    as_of = T0 + timedelta(hours=12)
    fast = ledger.stats(by, since, until, as_of=as_of, calendar=BERLIN)
    fine = ledger.stats(by, since, until, codes=["*"], as_of=as_of, calendar=BERLIN)
    assert fast == fine
    assert sum(r.confirmations for r in fast) >= 12


def test_busy_log_figures(ledger: FaultLedger) -> None:
    as_of = T0 + timedelta(hours=12)
    rows = ledger.stats("10min", T0, T0 + timedelta(minutes=10), as_of=as_of)
    assert len(rows) == 1
    row = rows[0]
    assert row.confirmations == 12 and row.heals == 12
    assert row.flood_windows == 1 and row.flood_seconds == 600.0 and row.flood_percent == 100.0
    assert row.top10_share == pytest.approx(10 / 12)
    assert row.active_seconds == pytest.approx(12 * 7 + 600)  # + LIDAR_DIRTY, confirmed all along
    assert row.mttr_seconds == pytest.approx(7)
    chatter = ledger.stats("hour", T0 + timedelta(hours=3), T0 + timedelta(hours=4),
                           as_of=as_of)[0]
    assert chatter.activations == 4 and chatter.chattering_codes == 1
    stale = ledger.stats("day", T0 - timedelta(days=2), T0 + timedelta(days=1), as_of=as_of,
                         calendar=BERLIN)
    assert [(r.period.id, r.stale_codes) for r in stale] == [
        ("2026-11-18", 0), ("2026-11-19", 0), ("2026-11-20", 1), ("2026-11-21", 1)]


def test_open_episode_ends_at_as_of(ledger: FaultLedger) -> None:
    start = T0 + timedelta(hours=9)
    for minutes in (10, 45):
        as_of = start + timedelta(minutes=minutes)
        rows = ledger.stats("hour", start, start + timedelta(hours=1), codes=["MOTOR_HOT"],
                            as_of=as_of)
        assert rows[0].active_seconds == pytest.approx(minutes * 60 - 1)
        fast = ledger.stats("hour", start, start + timedelta(hours=1), as_of=as_of)[0]
        assert fast.active_seconds >= rows[0].active_seconds


def test_group_by_code_adds_up_to_the_total(ledger: FaultLedger) -> None:
    since, until = T0 - timedelta(days=1), T0 + timedelta(days=1)
    as_of = T0 + timedelta(hours=12)
    total = ledger.stats("shift", since, until, as_of=as_of)
    grouped = ledger.stats("shift", since, until, group_by=["code"], as_of=as_of)
    for field in ("failed_reports", "passed_reports", "activations", "confirmations", "heals",
                  "repairs"):
        assert sum(getattr(r, field) for r in grouped) == sum(getattr(r, field) for r in total)
    assert sum(r.active_seconds for r in grouped) == pytest.approx(
        sum(r.active_seconds for r in total))
    assert {r.group["code"] for r in grouped} >= {"ESTOP", "GRIPPER_CHATTER", "LIDAR_DIRTY"}


def test_glob_selects_codes(ledger: FaultLedger) -> None:
    rows = ledger.stats("day", T0 - timedelta(hours=6), T0 + timedelta(hours=18),
                        codes=["FLOOD_0*", "ESTOP"], as_of=T0 + timedelta(hours=12))
    assert sum(r.activations for r in rows) == 10 + 1


def test_upgrade_from_0001_computes_statistics_from_the_log(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    ledger = FaultLedger.open(url(path), policy=HEALING, background=False)
    busy_log(ledger)
    as_of = T0 + timedelta(hours=12)
    before = ledger.stats("hour", T0 - timedelta(days=1), T0 + timedelta(days=1), as_of=as_of)
    ledger.close()
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    engine = create_engine(url(path))
    with engine.connect() as conn:
        config.attributes["connection"] = conn
        command.downgrade(config, "0001_initial")
        conn.commit()
    engine.dispose()
    with contextlib.closing(sqlite3.connect(path)) as raw:
        raw.execute("DELETE FROM checkpoints WHERE name = 'statistics'")
        raw.commit()
    reopened = FaultLedger.open(url(path), background=False)
    try:
        after = reopened.stats("hour", T0 - timedelta(days=1), T0 + timedelta(days=1),
                               as_of=as_of)
        assert after == before
        assert reopened.verify().ok
    finally:
        reopened.close()


def test_restart_continues_the_fold(tmp_path: Path) -> None:
    """Chatter and activation state survive a restart: the third quick activation after a
    restart still chatters."""
    path = tmp_path / "faults.db"
    for i in range(3):
        ledger = FaultLedger.open(url(path), policy=HEALING, background=False)
        at = T0 + timedelta(seconds=10 * i)
        ledger.report("FLAKY", "FAILED", source_id="/x", at=at)
        ledger.report("FLAKY", "PASSED", source_id="/x", at=at + timedelta(seconds=1))
        ledger.close()
    ledger = FaultLedger.open(url(path), background=False)
    try:
        row = ledger.stats("hour", T0, T0 + timedelta(hours=1))[0]
        assert (row.activations, row.chattering_codes) == (3, 1)
        assert ledger.verify().ok
    finally:
        ledger.close()


def test_berlin_day_and_hour_periods_follow_dst() -> None:
    spring = datetime(2026, 3, 29, tzinfo=UTC) - timedelta(hours=1)  # local midnight
    days = periods("day", spring, spring + timedelta(hours=23), BERLIN)
    assert [(p.id, (p.end - p.start).total_seconds() / 3600) for p in days] == [
        ("2026-03-29", 23.0)]
    fall_night = datetime(2026, 10, 24, 22, tzinfo=UTC)  # 00:00 CEST on Oct 25
    hours = periods("hour", fall_night, fall_night + timedelta(hours=5), BERLIN)
    assert [p.id for p in hours] == [
        "2026-10-25T00:00+02:00", "2026-10-25T01:00+02:00", "2026-10-25T02:00+02:00",
        "2026-10-25T02:00+01:00", "2026-10-25T03:00+01:00"]
    tens = periods("10min", fall_night + timedelta(minutes=5), fall_night + timedelta(minutes=25),
                   BERLIN)
    assert [(p.start.minute, p.end.minute) for p in tens] == [(5, 10), (10, 20), (20, 25)]


def test_bounds_accept_dates_datetimes_and_shift_ids() -> None:
    assert parse_bound("2026-11-21", BERLIN, upper=False) == datetime(2026, 11, 20, 23,
                                                                      tzinfo=UTC)
    assert parse_bound("2026-11-21T06:30", BERLIN, upper=False) == datetime(
        2026, 11, 21, 5, 30, tzinfo=UTC)
    assert parse_bound("2026-11-21T06:30+00:00", BERLIN, upper=True) == datetime(
        2026, 11, 21, 6, 30, tzinfo=UTC)
    assert parse_bound("2026-11-21/night", BERLIN, upper=False) == datetime(
        2026, 11, 21, 21, tzinfo=UTC)
    assert parse_bound("2026-11-21/night", BERLIN, upper=True) == datetime(
        2026, 11, 22, 5, tzinfo=UTC)


def test_shift_id_bounds_give_that_shift(ledger: FaultLedger) -> None:
    rows = ledger.stats("shift", "2026-11-20/morning", "2026-11-20/morning", calendar=BERLIN,
                        as_of=T0 + timedelta(hours=12))
    assert [r.period.id for r in rows] == ["2026-11-20/morning"]
    assert rows[0].confirmations >= 12


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"by": "week"}, "by must be one of"),
    ({"group_by": ["line"]}, "group_by takes distinct names"),
    ({"group_by": ["code", "code"]}, "group_by takes distinct names"),
    ({"codes": "HW_*"}, "list of glob patterns"),
    ({"codes": [""]}, "non-empty glob patterns"),
    ({"since": "yesterday"}, "since: expected a date"),
    ({"until": "2026-11-21/lunch"}, "no shift 'lunch'"),
    ({"since": "2026-11-22", "until": "2026-11-21"}, "must be before until"),
    ({"since": datetime(2026, 11, 21)}, "timezone-aware"),
])
def test_bad_arguments_are_refused_clearly(ledger: FaultLedger, kwargs: dict[str, object],
                                           message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        ledger.stats(**kwargs)  # type: ignore[arg-type]
    assert isinstance(ledger.stats("hour")[0], StatsRow)


# -- goal outcomes, ranges that end now, the upgrade that added the goal tables ---------------

NAV, PICK = "/nav/navigate_to_pose", "/arm/pick"
CLI = [sys.executable, "-m", "faultledger.cli.main"]


def goals_log(ledger: FaultLedger) -> None:
    """busy_log plus goal outcomes: the navigation fault latches while its goals keep aborting;
    some outcomes fall in the seconds of a minute, some on a minute, a repeat is ignored."""
    busy_log(ledger)
    for i in range(6):
        at = T0 + timedelta(hours=2, seconds=37 * i, microseconds=123 * i)
        assert ledger.record_goal_outcome(NAV, f"nav-{i}", "ABORTED", "/bt_navigator",
                                          at=at).accepted
    statuses = ("SUCCEEDED", "CANCELED", "ABORTED", "SUCCEEDED")
    for i, status in enumerate(statuses):
        at = T0 + timedelta(hours=5, minutes=30, seconds=10 + i)  # the ESTOP's minute
        assert ledger.record_goal_outcome(PICK, f"pick-{i}", status, "/arm_server",
                                          at=at).accepted
    assert ledger.record_goal_outcome(PICK, "pick-4", "ABORTED", "", at=T0 + timedelta(
        hours=9)).accepted
    assert ledger.record_goal_outcome(NAV, "nav-0", "ABORTED", "/bt_navigator").duplicate


@pytest.fixture
def goals_ledger(tmp_path: Path) -> Iterator[FaultLedger]:
    opened = FaultLedger.open(url(tmp_path / "goals.db"), policy=HEALING, background=False)
    goals_log(opened)
    yield opened
    opened.close()


def goal_counts(rows: list[StatsRow]) -> tuple[int, int, int]:
    return (sum(r.aborted_goals for r in rows), sum(r.canceled_goals for r in rows),
            sum(r.succeeded_goals for r in rows))


def test_group_by_action_gives_one_row_per_action_and_period(goals_ledger: FaultLedger) -> None:
    since, until = T0, T0 + timedelta(hours=12)
    as_of = T0 + timedelta(hours=12)
    total = goals_ledger.stats("hour", since, until, as_of=as_of)
    grouped = goals_ledger.stats("hour", since, until, group_by=["action"], as_of=as_of)
    assert goal_counts(grouped) == goal_counts(total) == (6 + 1 + 1, 1, 2)
    assert [(r.period.start - T0, r.group, r.aborted_goals, r.canceled_goals,
             r.succeeded_goals) for r in grouped] == [
        (timedelta(hours=2), {"action": NAV}, 6, 0, 0),
        (timedelta(hours=5), {"action": PICK}, 1, 1, 2),
        (timedelta(hours=9), {"action": PICK}, 1, 0, 0)]
    for row in grouped:  # faults have no action: their figures are empty in these rows
        assert (row.failed_reports, row.activations, row.confirmations, row.active_seconds,
                row.repairs, row.stale_codes) == (0, 0, 0, 0.0, 0, 0)
        assert (row.mttr_seconds, row.mtbf_seconds, row.top10_share) == (None, None, None)
    by_server = goals_ledger.stats("day", since, until, group_by=["action", "source"],
                                   as_of=as_of)
    assert [(r.group, r.aborted_goals) for r in by_server] == [  # in key order
        ({"action": PICK, "source": ""}, 1),
        ({"action": PICK, "source": "/arm_server"}, 1),
        ({"action": NAV, "source": "/bt_navigator"}, 6)]
    by_code = goals_ledger.stats("hour", since, until, group_by=["code"], as_of=as_of)
    assert goal_counts(by_code) == (0, 0, 0)  # goals have no code
    assert sum(r.activations for r in by_code) == sum(r.activations for r in total)


def test_codes_do_not_select_goal_outcomes(goals_ledger: FaultLedger) -> None:
    """`codes` are fault code patterns; a goal outcome has no code, so the e-stops and the
    aborted goals of a shift come from one query."""
    as_of = T0 + timedelta(hours=12)
    rows = goals_ledger.stats("shift", T0, T0 + timedelta(hours=12), codes=["ESTOP"],
                              as_of=as_of)
    assert sum(r.activations for r in rows) == 1
    assert goal_counts(rows) == (8, 1, 2)


@pytest.mark.parametrize("group_by", [["action", "code"], ["severity", "action"]])
def test_action_combines_only_with_source(goals_ledger: FaultLedger,
                                          group_by: list[str]) -> None:
    with pytest.raises(InvalidInputError, match="group_by action combines only with source"):
        goals_ledger.stats("hour", group_by=group_by)


UNALIGNED = [
    (T0 - timedelta(hours=1, seconds=-7), T0 + timedelta(hours=5, minutes=30, seconds=11)),
    (T0 + timedelta(hours=2, seconds=30), T0 + timedelta(hours=2, seconds=75, microseconds=5)),
    (T0 + timedelta(hours=2, seconds=1), T0 + timedelta(hours=2, seconds=40)),  # one minute
    (T0 + timedelta(minutes=1, seconds=21), T0 + timedelta(hours=9, microseconds=1)),
    (T0 - timedelta(days=1), T0 + timedelta(hours=5, minutes=30, seconds=10, microseconds=1)),
]


@pytest.mark.parametrize("by", ["shift", "day", "hour", "10min"])
@pytest.mark.parametrize(("since", "until"), UNALIGNED)
def test_minute_path_with_partial_minutes_equals_fact_path(
    goals_ledger: FaultLedger, by: str, since: datetime, until: datetime
) -> None:
    """Whole minutes from the minute table, the partial first and last minute from facts:
    every figure equals the fact path's, goal figures included."""
    for as_of in (until, T0 + timedelta(hours=5, minutes=30, seconds=20), T0 + timedelta(
            hours=12)):
        fast = goals_ledger.stats(by, since, until, as_of=as_of, calendar=BERLIN)
        fine = goals_ledger.stats(by, since, until, codes=["*"], as_of=as_of, calendar=BERLIN)
        assert fast == fine
    assert sum(r.failed_reports for r in fast) > 0 or goal_counts(fast) != (0, 0, 0)


def test_flood_over_a_partial_minute_is_found_on_both_paths(tmp_path: Path) -> None:
    """Ten confirmations in whole minutes and the eleventh in the partial last minute make a
    flood window; the minute path must not miss it."""
    with FaultLedger.open(url(tmp_path / "f.db"), policy=HEALING, background=False) as ledger:
        for i in range(11):
            at = T0 + timedelta(minutes=i // 2, seconds=30 * (i % 2) + 1)
            assert ledger.report(f"F{i}", "FAILED", 3, "", "/cell", at=at).accepted
        until = T0 + timedelta(minutes=5, seconds=2)
        fast = ledger.stats("10min", T0, until, as_of=until)
        fine = ledger.stats("10min", T0, until, codes=["*"], as_of=until)
    assert fast == fine
    assert (fast[0].confirmations, fast[0].flood_windows) == (11, 1)


def test_a_range_with_no_end_ends_now(tmp_path: Path) -> None:
    """SPEC §7: what happened a second ago is counted, also in the current minute."""
    with FaultLedger.open(url(tmp_path / "now.db"), policy=HEALING, background=False) as ledger:
        second_ago = datetime.now(UTC) - timedelta(seconds=1)
        assert ledger.report("ESTOP", "FAILED", 3, "", "/safety", at=second_ago).accepted
        assert ledger.report("ESTOP", "PASSED", 0, "", "/safety").accepted  # at: now
        assert ledger.report("ESTOP", "FAILED", 3, "", "/safety").accepted
        assert ledger.record_goal_outcome(NAV, "g1", "ABORTED", "/bt").accepted
        for by in ("shift", "day", "hour", "10min"):
            rows = ledger.stats(by)
            assert sum(r.activations for r in rows) == 2, by
            assert goal_counts(rows) == (1, 0, 0), by
            now = datetime.now(UTC)
            assert ledger.stats(by, as_of=now) == ledger.stats(by, codes=["*"], as_of=now), by
        before = datetime.now(UTC)
        until = ledger.stats("hour")[-1].period.end
        assert before < until <= datetime.now(UTC) + timedelta(microseconds=1)


def test_a_report_stamped_with_as_of_itself_is_counted(tmp_path: Path) -> None:
    """A datetime holds microseconds: a range with no end ends just after ``as_of``, so a
    report stamped with that very datetime counts; an explicit ``until`` stays exclusive."""
    at = datetime(2026, 11, 21, 10, 15, 30, 123456, tzinfo=UTC)
    with FaultLedger.open(url(tmp_path / "at.db"), policy=HEALING, background=False) as ledger:
        assert ledger.report("ESTOP", "FAILED", 3, "", "/safety", at=at).accepted
        assert ledger.record_goal_outcome(NAV, "g1", "CANCELED", "/bt", at=at).accepted
        for codes in (None, ["*"]):
            [row] = ledger.stats("hour", as_of=at, codes=codes)[-1:]
            assert (row.activations, row.canceled_goals) == (1, 1)
            assert row.period.end == at + timedelta(microseconds=1)
            [row] = ledger.stats("hour", since=at - timedelta(minutes=1), until=at,
                                 codes=codes, as_of=at)[-1:]
            assert (row.activations, row.canceled_goals) == (0, 0)


def test_the_cli_counts_a_report_made_a_second_before(tmp_path: Path) -> None:
    """Through the CLI in subprocesses: `report` now, then `stats` and the current shift's
    `report-shift` count it (and the goal outcome recorded with it)."""
    db = url(tmp_path / "cli.db")
    for _ in range(3):  # a shift change between the commands would change the shift: retry
        current = default_calendar().shift_at(datetime.now(UTC))
        assert current is not None
        done = subprocess.run([*CLI, "report", "ESTOP", "FAILED", "--severity", "CRITICAL",
                               "--source", "/safety", "--db", db],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        with FaultLedger.open(db, background=False) as ledger:
            assert ledger.record_goal_outcome(NAV, f"g-{current.id}", "ABORTED").accepted
        stats = subprocess.run([*CLI, "stats", "--by", "10min", "--json", "--db", db],
                               capture_output=True, text=True, timeout=60)
        shift = subprocess.run([*CLI, "report-shift", current.id, "--db", db],
                               capture_output=True, text=True, timeout=60)
        if default_calendar().shift_at(datetime.now(UTC)) == current:
            break
    assert stats.returncode == 0, stats.stderr
    rows = json.loads(stats.stdout)
    assert sum(r["activations"] for r in rows) >= 1
    assert sum(r["aborted_goals"] for r in rows) >= 1
    assert shift.returncode == 0, shift.stderr
    assert "in progress" in shift.stdout
    figures = {line.split("│")[1].strip(): line.split("│")[2].strip()
               for line in shift.stdout.splitlines() if line.startswith("│")
               and line.count("│") == 6}
    assert figures["activations (all faults)"] == "1" and figures["aborted goals"] == "1"


def test_upgrade_from_0002_computes_zero_goals_then_counts_new_ones(tmp_path: Path) -> None:
    """An 0002 database cannot hold goal records: after the upgrade its statistics are
    recomputed from the log (the same figures, zero goals), and new goal outcomes count."""
    path = tmp_path / "faults.db"
    as_of = T0 + timedelta(hours=12)
    with FaultLedger.open(url(path), policy=HEALING, background=False) as ledger:
        busy_log(ledger)
        before = ledger.stats("hour", T0 - timedelta(days=1), T0 + timedelta(days=1),
                              as_of=as_of)
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    engine = create_engine(url(path))
    with engine.connect() as conn:
        config.attributes["connection"] = conn
        command.downgrade(config, "0002_statistics")
        conn.commit()
    engine.dispose()
    with contextlib.closing(sqlite3.connect(path)) as raw:
        tables = {r[0] for r in raw.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        assert "stat_goals" not in tables
        columns = {r[1] for r in raw.execute("PRAGMA table_info(stat_minutes)")}
        assert "aborted_goals" not in columns
        # As 0002 left it: statistics up to date with the projections.
        raw.execute("UPDATE checkpoints SET seq = (SELECT seq FROM checkpoints WHERE "
                    "name = 'projection') WHERE name = 'statistics'")
        raw.commit()
    engine = create_engine(url(path))
    with engine.connect() as conn:
        config.attributes["connection"] = conn
        command.upgrade(config, "head")
        conn.commit()
    engine.dispose()
    with contextlib.closing(sqlite3.connect(path)) as raw:  # the next open recomputes them
        assert raw.execute("SELECT seq FROM checkpoints WHERE name = 'statistics'"
                           ).fetchall() == [(0,)]
        assert raw.execute("SELECT count(*) FROM stat_goals").fetchall() == [(0,)]
    with FaultLedger.open(url(path), policy=HEALING, background=False) as ledger:
        after = ledger.stats("hour", T0 - timedelta(days=1), T0 + timedelta(days=1),
                             as_of=as_of)
        assert after == before
        assert goal_counts(after) == (0, 0, 0)
        assert ledger.verify().ok
        assert ledger.record_goal_outcome(NAV, "g1", "ABORTED", "/bt",
                                          at=T0 + timedelta(hours=2)).accepted
        assert ledger.record_goal_outcome(NAV, "g2", "SUCCEEDED", "/bt",
                                          at=T0 + timedelta(hours=2, seconds=1)).accepted
    with FaultLedger.open(url(path), background=False) as ledger:
        rows = ledger.stats("hour", T0 - timedelta(days=1), T0 + timedelta(days=1),
                            as_of=as_of)
        assert goal_counts(rows) == (1, 0, 1)
        assert rows == ledger.stats("hour", T0 - timedelta(days=1), T0 + timedelta(days=1),
                                    codes=["*"], as_of=as_of)
        assert ledger.verify().ok
