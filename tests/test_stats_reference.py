"""Statistics equal a plain fold over the raw log, for every metric, period and group
(docs/statistics.md; SPEC §7 "Statistics must equal a recomputation from the raw log"),
goal outcomes included, and for ranges with no end (they end at ``as_of``)."""

from __future__ import annotations

import re
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any
from zoneinfo import ZoneInfo

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faultledger import FaultLedger, Policy
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import StatsRow
from tests.stats_reference import (
    ExpectedRow,
    RefPeriod,
    SimpleShift,
    differences,
    expected_rows,
    fold,
    grid_periods,
    shift_periods,
)

T0 = datetime(2026, 11, 16, 20, 0, tzinfo=UTC)
"""Monday 20:00 UTC (21:00 in Berlin, UTC+1 then, far from any DST switch)."""
BASES = (
    T0,
    datetime(2026, 3, 28, 20, 0, tzinfo=UTC),   # Berlin springs forward 29 March 01:00 UTC
    datetime(2026, 10, 24, 20, 0, tzinfo=UTC),  # Berlin falls back 25 October 01:00 UTC
)
"""Where a log starts: the 28 hours after each include a night, midnight and, for the last
two, a DST switch in Berlin (a 7 h / 9 h night, a 23 h / 25 h day, a repeated hour)."""
US = 1_000_000
HOUR_US = 3600 * US

CODES = ("HW_ARM_EMERGENCY_STOP", "HW_BASE_STOP", "LIDAR_TIMEOUT", "MOTOR_OVERHEAT")
"""One e-stop code of the default ``estop_codes`` among others."""
SOURCES = ("/arm", "/base", "/sensors/lidar")
ACTORS = ("cli:alice", "cli:bob")
ACTIONS = ("/nav/navigate_to_pose", "/arm/pick", "/dock")
GOAL_IDS = tuple(f"goal-{i}" for i in range(6))
"""Few, so goals repeat: a repeat of (action, goal id) is stored once."""
SERVERS = ("", "/bt_navigator", "/arm_server")
GOAL_STATUSES = ("SUCCEEDED", "ABORTED", "CANCELED")
POLICIES = (
    Policy(),
    Policy(confirmation_threshold=-3, healing_enabled=True, healing_threshold=3),
    Policy(confirmation_threshold=-2, healing_enabled=True, healing_threshold=0,
           auto_confirm_after_sec=30.0),
    Policy(healing_enabled=True, healing_threshold=1),
)

# Offsets from the base that fall on period boundaries: 10-minute slots, hours, and (from T0)
# UTC and Berlin shift changes (21:00, 22:00, 05:00, 06:00 UTC) and days (23:00, 00:00 UTC).
BOUNDARIES_US = (*(h * HOUR_US for h in (0, 1, 2, 3, 4, 9, 10, 25, 26)),
                 (2 * 3600 + 600) * US, (4 * 3600 + 1200) * US, (26 * 3600 + 3000) * US)

THREE_SHIFTS = (SimpleShift("morning", 6, 14), SimpleShift("afternoon", 14, 22),
                SimpleShift("night", 22, 6))


def _calendar(zone: str, shifts: Sequence[SimpleShift]) -> ShiftCalendar:
    return ShiftCalendar.model_validate({
        "timezone": zone,
        "shifts": [{"name": s.name, "start": f"{s.start_hour:02d}:00",
                    "end": f"{s.end_hour:02d}:00"} for s in shifts],
    })


@dataclass(frozen=True)
class Calendar:
    """The calendar passed to ``stats`` (None: the default) and what it means."""

    given: ShiftCalendar | None
    zone: ZoneInfo
    shifts: tuple[SimpleShift, ...]


CALENDARS = {
    "default": Calendar(None, ZoneInfo("UTC"), THREE_SHIFTS),
    "utc": Calendar(_calendar("UTC", THREE_SHIFTS), ZoneInfo("UTC"), THREE_SHIFTS),
    "berlin": Calendar(_calendar("Europe/Berlin", THREE_SHIFTS), ZoneInfo("Europe/Berlin"),
                       THREE_SHIFTS),
    "berlin-no-night": Calendar(_calendar("Europe/Berlin", THREE_SHIFTS[:2]),
                                ZoneInfo("Europe/Berlin"), THREE_SHIFTS[:2]),
}

BYS = ("shift", "hour", "10min", "day")
QUERIES: tuple[tuple[tuple[str, ...] | None, tuple[str, ...]], ...] = (
    (None, ()),                       # per-minute sums (+ partial minutes from facts)
    (("*",), ()),                     # the same over facts: both paths
    (("HW_*_STOP",), ()),
    (None, ("code",)),
    (None, ("source", "severity")),
    (("HW_*_STOP", "LIDAR_*"), ("code",)),
    (None, ("action",)),
    (("HW_*_STOP",), ("source", "action")),
)


# -- the operations that build a log ----------------------------------------------------------

@dataclass(frozen=True)
class When:
    """Advance the clock by ``step_us``; or, with ``absolute_us``, report at base + that without
    moving the clock (a boundary, or a reporter whose clock is off: out of order)."""

    step_us: int
    absolute_us: int | None = None


@dataclass(frozen=True)
class Report:
    code: str
    failed: bool
    severity: int
    source: str
    when: When


@dataclass(frozen=True)
class Clear:
    code: str
    actor: str
    when: When


@dataclass(frozen=True)
class Timer:
    when: When


@dataclass(frozen=True)
class Goal:
    action: str
    goal_id: str
    status: str
    server: str
    when: When


@dataclass(frozen=True)
class Jump:
    """Move the clock to the next day (base + 24 h + offset), so episodes can become stale."""

    offset_us: int


@dataclass(frozen=True)
class Restart:
    policy: int


@dataclass(frozen=True)
class Burst:
    """``pairs`` × (CRITICAL FAILED, clear), ``gap_s`` apart: a flood of confirmations."""

    code: str
    source: str
    pairs: int
    gap_s: int


@dataclass(frozen=True)
class Operate:
    """An acknowledgement, a shelving for ``minutes``, or an unshelving, by an actor."""

    action: str
    code: str
    actor: str
    minutes: int
    when: When


Op = Report | Clear | Timer | Goal | Jump | Restart | Burst | Operate

steps = st.one_of(
    st.integers(0, 40).map(lambda s: s * US),          # chattering range
    st.integers(0, 1800).map(lambda s: s * US),
    st.integers(0, 900 * US),                           # microsecond times
    st.sampled_from([600 * US, HOUR_US]),
)
absolutes = st.sampled_from(("clock",) * 5 + ("boundary", "anywhere")).flatmap(
    lambda kind: st.none() if kind == "clock" else st.sampled_from(BOUNDARIES_US)
    if kind == "boundary" else st.integers(0, 11 * HOUR_US))
whens = st.builds(When, steps, absolutes)
reports = st.builds(Report, st.sampled_from(CODES), st.booleans(), st.integers(0, 3),
                    st.sampled_from(SOURCES), whens)
KINDS = (("report",) * 14 + ("clear",) * 3 + ("goal",) * 4 + ("operate",) * 3
         + ("timer", "jump", "restart"))
"""Weights of the operations (repeated branches of ``st.one_of`` would not weigh more)."""


@st.composite
def plain_ops(draw: st.DrawFn) -> Op:
    """Reports of FAILED and PASSED, clears, timer runs, a jump to the next day, restarts."""
    kind = draw(st.sampled_from(KINDS))
    if kind == "report":
        return draw(reports)
    if kind == "clear":
        return draw(st.builds(Clear, st.sampled_from(CODES), st.sampled_from(ACTORS), whens))
    if kind == "timer":
        return draw(st.builds(Timer, whens))
    if kind == "operate":
        return draw(st.builds(Operate, st.sampled_from(["ack", "ack", "shelve", "unshelve"]),
                              st.sampled_from(CODES), st.sampled_from(ACTORS),
                              st.integers(1, 300), whens))
    if kind == "goal":
        return draw(st.builds(Goal, st.sampled_from(ACTIONS), st.sampled_from(GOAL_IDS),
                              st.sampled_from(GOAL_STATUSES), st.sampled_from(SERVERS), whens))
    if kind == "jump":
        return draw(st.builds(Jump, st.integers(0, 2 * HOUR_US)))
    return draw(st.builds(Restart, st.integers(0, len(POLICIES) - 1)))


bursts = st.builds(Burst, st.sampled_from(CODES), st.sampled_from(SOURCES), st.integers(11, 12),
                   st.integers(1, 25))


@st.composite
def logs(draw: st.DrawFn) -> list[Op]:
    """At most 34 plain operations and maybe one burst: at most 60 records with the policy."""
    ops: list[Op] = draw(st.lists(plain_ops(), min_size=10, max_size=34))
    burst = draw(bursts) if draw(st.integers(0, 3)) == 0 else None
    if burst is not None:
        ops.insert(draw(st.integers(0, len(ops))), burst)
    return ops


def _open(url: str, policy: int) -> FaultLedger:
    return FaultLedger.open(url, policy=POLICIES[policy], background=False)


_MAKE_URL: list[Callable[[str], str]] = []
"""``fresh_url`` under ``--backend postgresql`` (set by the autouse fixture below):
hypothesis examples are many per test, so each example asks for a fresh database itself."""


@pytest.fixture(autouse=True)
def _backend_urls(backend: str, fresh_url: Callable[[str], str]) -> Iterator[None]:
    if backend == "postgresql":
        _MAKE_URL.append(fresh_url)
    yield
    if backend == "postgresql":
        _MAKE_URL.pop()


@contextmanager
def built(ops: Sequence[Op], policy: int, base: datetime) -> Iterator[tuple[FaultLedger, str]]:
    """A ledger on a fresh log (a SQLite file in a temporary directory per example, or a
    PostgreSQL database) holding the log the operations write through the public API, its
    clock starting at ``base``."""
    with tempfile.TemporaryDirectory(prefix="faultledger-stats-") as tmp:
        url = _MAKE_URL[-1]("stats") if _MAKE_URL else f"sqlite:///{Path(tmp) / 'stats.db'}"
        ledger = _open(url, policy)
        try:
            clock = base
            for op in ops:
                if isinstance(op, Restart):
                    ledger.close()
                    ledger = _open(url, op.policy)
                elif isinstance(op, Jump):
                    clock = base + timedelta(days=1, microseconds=op.offset_us)
                elif isinstance(op, Burst):
                    for _ in range(op.pairs):
                        result = ledger.report(op.code, "FAILED", 3, "", op.source, at=clock)
                        assert result.accepted, result.message
                        clock += timedelta(seconds=op.gap_s)
                        assert ledger.clear(op.code, actor="cli:flood", at=clock).success
                        clock += timedelta(seconds=op.gap_s)
                else:
                    clock += timedelta(microseconds=op.when.step_us)
                    at = clock if op.when.absolute_us is None else (
                        base + timedelta(microseconds=op.when.absolute_us))
                    if isinstance(op, Report):
                        result = ledger.report(op.code, "FAILED" if op.failed else "PASSED",
                                               op.severity, "", op.source, at=at)
                        assert result.accepted, result.message
                    elif isinstance(op, Clear):
                        ledger.clear(op.code, actor=op.actor, at=at)  # may be "not found"
                    elif isinstance(op, Goal):
                        result = ledger.record_goal_outcome(op.action, op.goal_id, op.status,
                                                            op.server, at=at)
                        assert result.accepted, result.message
                    elif isinstance(op, Operate):  # may be refused: it is then not counted
                        if op.action == "ack":
                            ledger.acknowledge(op.code, op.actor, at=at)
                        elif op.action == "shelve":
                            ledger.shelve(op.code, op.minutes * 60, op.actor, at=at)
                        else:
                            ledger.unshelve(op.code, op.actor, at=at)
                    else:
                        ledger.run_timers(at)
            yield ledger, url
        finally:
            ledger.close()


# -- query ranges ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Range:
    base: datetime
    """Where the log starts (see BASES); the bounds below are near it."""
    since: datetime
    until: datetime
    as_of: datetime
    as_text: bool
    """Pass since/until as ISO strings with an offset instead of datetimes."""
    open_end: bool = False
    """Pass no until: the range ends just after ``as_of`` (``until`` = as_of + 1 µs)."""


@st.composite
def ranges(draw: st.DrawFn) -> Range:
    base = draw(st.sampled_from(BASES))

    def _at(us: int) -> datetime:
        return base + timedelta(microseconds=us)

    aligned = draw(st.booleans())
    if aligned:  # whole minutes: the minute-table path may be used
        since = _at(draw(st.sampled_from([-HOUR_US, 0, 90 * 60 * US, 3 * HOUR_US]))
                    + draw(st.integers(0, 30)) * 60 * US)
        until = _at(draw(st.sampled_from([11 * HOUR_US, 28 * HOUR_US]))
                    + draw(st.integers(0, 30)) * 60 * US)
    else:  # seconds and microseconds: the facts/episodes path
        since = _at(draw(st.integers(-HOUR_US, 3 * HOUR_US)))
        until = _at(draw(st.one_of(st.integers(5 * HOUR_US, 11 * HOUR_US),
                                   st.integers(25 * HOUR_US, 28 * HOUR_US))))
    as_of = draw(st.one_of(st.just(until), st.just(_at(30 * HOUR_US)),
                           st.builds(_at, st.integers(0, 28 * HOUR_US))))
    if draw(st.integers(0, 3)) == 0:  # no until: it ends at as_of, wherever that is
        as_of = since + timedelta(microseconds=draw(st.one_of(
            st.integers(0, 28 * HOUR_US), st.integers(0, 28 * 60).map(lambda m: m * 60 * US))))
        return Range(base, since, as_of + timedelta(microseconds=1), as_of,
                     draw(st.booleans()), open_end=True)
    return Range(base, since, until, as_of, draw(st.booleans()))


# -- checking ----------------------------------------------------------------------------------

def reference_periods(by: str, calendar: Calendar, since: datetime, until: datetime
                      ) -> list[RefPeriod]:
    if by == "shift":
        periods = shift_periods(calendar.zone, calendar.shifts, since, until)
        real = (calendar.given or CALENDARS["utc"].given)
        assert real is not None
        assert [(p.id, p.start, p.end) for p in periods] == [
            (p.id, p.start, p.end) for p in real.periods(since, until)]
        return periods
    return grid_periods(by, calendar.zone, since, until)


def without_offset(period_id: str) -> str:
    """``2026-11-16T21:00+01:00`` → ``2026-11-16T21:00``: the property tests check figures;
    the id format is checked on its own by
    ``test_hour_and_10min_period_ids_are_local_clock_times_as_documented``."""
    return re.sub(r"(T\d\d:\d\d)(?:[+-]\d\d:\d\d|Z)$", r"\1", period_id)


def stats(ledger: FaultLedger, by: str, calendar: Calendar, window: Range,
          codes: Sequence[str] | None, group_by: Sequence[str]) -> list[StatsRow]:
    since: datetime | str = window.since
    until: datetime | str | None = window.until
    if window.as_text:
        since, until = window.since.isoformat(), window.until.isoformat()
    if window.open_end:
        until = None
    return ledger.stats(by=by, since=since, until=until,
                        codes=None if codes is None else list(codes), group_by=list(group_by),
                        calendar=calendar.given, as_of=window.as_of)


def _describe(by: str, calendar: str, window: Range, codes: Sequence[str] | None,
              group_by: Sequence[str]) -> str:
    return (f"stats(by={by!r}, since={window.since.isoformat()!r}, "
            f"until={window.until.isoformat()!r}, codes={codes}, group_by={list(group_by)}, "
            f"calendar={calendar}, as_of={window.as_of.isoformat()!r}, "
            f"as_text={window.as_text}, open_end={window.open_end})")


def check_against_reference(ledger: FaultLedger, calendar_name: str, window: Range
                            ) -> dict[tuple[str, Any, Any], list[StatsRow]]:
    """Every query against the fold of ``ledger.history()``; returns the rows it got."""
    calendar = CALENDARS[calendar_name]
    folded = fold(ledger.history())
    problems: list[str] = []
    got: dict[tuple[str, Any, Any], list[StatsRow]] = {}
    for by in BYS:
        periods = reference_periods(by, calendar, window.since, window.until)
        for codes, group_by in QUERIES:
            rows = stats(ledger, by, calendar, window, codes, group_by)
            got[(by, codes, group_by)] = rows
            wanted = expected_rows(folded, periods, window.as_of, codes, group_by)
            found = differences(rows, wanted, without_offset)
            if found:
                problems.append(_describe(by, calendar_name, window, codes, group_by))
                problems.extend("    " + line for line in found[:12])
    assert not problems, "stats differ from the fold of the log:\n" + "\n".join(problems)
    return got


def as_expected(rows: Sequence[StatsRow]) -> list[ExpectedRow]:
    """Rows of one answer in the reference's shape, to compare two answers field by field."""
    return [ExpectedRow(RefPeriod(r.period.id, r.period.start, r.period.end, r.period.name,
                                  r.period.production_day),
                        dict(r.group), {name: getattr(r, name) for name in r.__dataclass_fields__
                                        if name not in ("period", "group")})
            for r in rows]


def assert_same_answers(before: dict[tuple[str, Any, Any], list[StatsRow]],
                        after: dict[tuple[str, Any, Any], list[StatsRow]]) -> None:
    problems: list[str] = []
    for query, rows in before.items():
        found = differences(after[query], as_expected(rows))
        if found:
            problems.append(f"{query}:")
            problems.extend("    " + line for line in found[:12])
    assert not problems, "\n".join(problems)


DB_SETTINGS = settings(max_examples=60, deadline=None,
                       suppress_health_check=[HealthCheck.too_slow,
                                              HealthCheck.data_too_large,
                                              HealthCheck.function_scoped_fixture])


@DB_SETTINGS
@given(policy=st.integers(0, len(POLICIES) - 1), ops=logs(),
       calendar=st.sampled_from(sorted(CALENDARS)), window=ranges())
def test_every_figure_of_every_row_equals_a_plain_fold_of_the_log(
    policy: int, ops: list[Op], calendar: str, window: Range
) -> None:
    with built(ops, policy, window.base) as (ledger, _):
        check_against_reference(ledger, calendar, window)


@settings(DB_SETTINGS, max_examples=20)
@given(policy=st.integers(0, len(POLICIES) - 1), ops=logs(),
       calendar=st.sampled_from(sorted(CALENDARS)), window=ranges())
def test_rebuild_leaves_the_statistics_unchanged(
    policy: int, ops: list[Op], calendar: str, window: Range
) -> None:
    with built(ops, policy, window.base) as (ledger, _):
        before = check_against_reference(ledger, calendar, window)
        ledger.rebuild()
        after = check_against_reference(ledger, calendar, window)
    assert_same_answers(before, after)


@settings(DB_SETTINGS, max_examples=20)
@given(policy=st.integers(0, len(POLICIES) - 1), ops=logs(),
       calendar=st.sampled_from(sorted(CALENDARS)), window=ranges())
def test_closing_and_reopening_the_ledger_leaves_the_statistics_unchanged(
    policy: int, ops: list[Op], calendar: str, window: Range
) -> None:
    with built(ops, policy, window.base) as (ledger, url):
        before = check_against_reference(ledger, calendar, window)
        ledger.close()
        with FaultLedger.open(url) as reader:  # no policy: opening writes nothing
            after = check_against_reference(reader, calendar, window)
        with FaultLedger.open(url, policy=POLICIES[policy], background=False) as writer:
            again = check_against_reference(writer, calendar, window)
    assert_same_answers(before, after)
    assert_same_answers(before, again)


def test_hour_and_10min_period_ids_are_local_clock_times_as_documented(tmp_path: Path) -> None:
    """docs/statistics.md, Periods: hour id `2026-11-21T06:00+01:00`, 10min id
    `2026-11-21T06:10+01:00` (local clock time of the calendar's zone and its UTC offset)."""
    since, until = T0, T0 + timedelta(minutes=70)  # 21:00-22:10 in Berlin
    with FaultLedger.open(f"sqlite:///{tmp_path / 'ids.db'}") as ledger:
        hours = ledger.stats(by="hour", since=since, until=until,
                             calendar=CALENDARS["berlin"].given, as_of=until)
        slots = ledger.stats(by="10min", since=since, until=until,
                             calendar=CALENDARS["berlin"].given, as_of=until)
        days = ledger.stats(by="day", since=since, until=until,
                            calendar=CALENDARS["berlin"].given, as_of=until)
    assert [r.period.id for r in hours] == ["2026-11-16T21:00+01:00", "2026-11-16T22:00+01:00"]
    assert [r.period.id for r in slots] == [
        f"2026-11-16T{hh}:{mm}+01:00" for hh, mm in [
            ("21", "00"), ("21", "10"), ("21", "20"), ("21", "30"), ("21", "40"), ("21", "50"),
            ("22", "00")]]
    assert [r.period.id for r in days] == ["2026-11-16"]


# -- the smallest cases the property tests found (kept as plain examples) ---------------------

def _repairs(ledger: FaultLedger, by: str, since: datetime, until: datetime,
             codes: list[str] | None) -> list[tuple[str, int, int, float | None]]:
    return [(without_offset(r.period.id), r.clears, r.repairs, r.mttr_seconds)
            for r in ledger.stats(by=by, since=since, until=until, codes=codes,
                                  calendar=CALENDARS["utc"].given, as_of=until)]


def test_an_episode_ending_exactly_at_since_is_a_repair_of_the_first_period_on_every_path(
    tmp_path: Path
) -> None:
    """"repairs: episodes that ended in the period" (start inclusive); "both paths give the
    same figures": with and without ``codes``."""
    with FaultLedger.open(f"sqlite:///{tmp_path / 'r.db'}", policy=Policy(),
                          background=False) as ledger:
        assert ledger.report("X", "FAILED", 0, "", "/arm",
                             at=T0 - timedelta(minutes=10)).accepted
        assert ledger.clear("X", actor="cli:alice", at=T0).success
        until = T0 + timedelta(hours=1)
        assert _repairs(ledger, "hour", T0, until, None) == [("2026-11-16T20:00", 1, 1, 600.0)]
        assert _repairs(ledger, "hour", T0, until, ["X"]) == [("2026-11-16T20:00", 1, 1, 600.0)]


def test_a_repair_belongs_to_the_period_of_the_record_that_ended_the_episode(
    tmp_path: Path
) -> None:
    """A clear whose reporter clock is behind (stamped before the confirmation): the clear and
    the repair both count where the clear's time lies; the repair lasted 0 s ("end − start, 0
    when the reporter's clock ran backwards")."""
    with FaultLedger.open(f"sqlite:///{tmp_path / 'r.db'}", policy=Policy(),
                          background=False) as ledger:
        assert ledger.report("X", "FAILED", 0, "", "/arm",
                             at=T0 + timedelta(minutes=15)).accepted
        assert ledger.clear("X", actor="cli:alice", at=T0 + timedelta(minutes=5)).success
        until = T0 + timedelta(minutes=20)
        expected = [("2026-11-16T20:00", 1, 1, 0.0), ("2026-11-16T20:10", 0, 0, None)]
        assert _repairs(ledger, "10min", T0, until, None) == expected
        assert _repairs(ledger, "10min", T0, until, ["X"]) == expected
