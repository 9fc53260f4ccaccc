"""Statistics: the per-minute path equals the per-fact path, periods, bounds, bad input, and
the first open after the upgrade that added the statistics tables."""

from __future__ import annotations

import contextlib
import sqlite3
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from alembic import command
from alembic.config import Config
from sqlalchemy import create_engine

from faultledger import FaultLedger, Policy, ShiftCalendar, StatsRow
from faultledger.domain.periods import parse_bound, periods
from faultledger.errors import InvalidInputError

MIGRATIONS = Path(__file__).resolve().parents[1] / "migrations"
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
