"""A plain, obviously-correct fold of the raw log into the figures of docs/statistics.md.

Used by the statistics tests as the reference `FaultLedger.stats` must equal. Everything is
done naively (loop over periods, loop over facts, integer nanoseconds) so that it can be
checked by reading it against the page, sentence by sentence.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, date, datetime, time, timedelta
from typing import Any
from zoneinfo import ZoneInfo

import pytest

from faultledger.domain.clock import to_ns
from faultledger.domain.events import (
    FaultAcknowledged,
    FaultCleared,
    FaultConfirmedByTimer,
    FaultReported,
    FaultShelved,
    FaultUnshelved,
    GoalOutcome,
    LogRecord,
    ReclassifiedOnStartup,
)
from faultledger.domain.projector import Projector
from faultledger.domain.shifts import UNSCHEDULED
from faultledger.domain.stat_rows import StatsRow
from faultledger.domain.types import EventType, FaultStatus

NS = 1_000_000_000
DAY_NS = 24 * 3600 * NS
STALE_NS = DAY_NS
CHATTER_NS = 60 * NS
FLOOD_WINDOW_NS = 600 * NS
FLOOD_LIMIT = 10

COUNTS = ("failed_reports", "passed_reports", "activations", "occurrences", "confirmations",
          "heals", "clears")
GOAL_COUNTS = {"ABORTED": "aborted_goals", "CANCELED": "canceled_goals",
               "SUCCEEDED": "succeeded_goals"}
ESTOP_GLOB = "HW_*_EMERGENCY_STOP"
"""The default ``estop_codes``."""
FIGURES = (*COUNTS, "estops", "active_seconds", "repairs", "mttr_seconds", "mtbf_seconds",
           "confirmations_per_10min", "flood_windows", "flood_seconds", "flood_percent",
           "chattering_codes", "stale_codes", "top10_share", *GOAL_COUNTS.values(),
           "acknowledgements", "mtta_seconds", "shelved_seconds")


# -- facts and episodes ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Fact:
    """One stored record that concerns a fault, with what it counts for."""

    seq: int
    at_ns: int
    code: str
    source: str
    severity: int
    failed_report: bool = False
    passed_report: bool = False
    activation: bool = False
    occurrence: bool = False
    confirmation: bool = False
    heal: bool = False
    clear: bool = False
    chattering: bool = False


@dataclass
class Episode:
    """A CONFIRMED episode: from a change to CONFIRMED to the next change away from it."""

    code: str
    source: str
    severity: int
    start_ns: int
    end_ns: int | None = None

    def end_or(self, as_of_ns: int) -> int:
        return as_of_ns if self.end_ns is None else self.end_ns


@dataclass(frozen=True)
class Goal:
    """One stored goal outcome record: the terminal status of one action goal."""

    seq: int
    at_ns: int
    action: str
    status: str
    server_node: str


@dataclass(frozen=True)
class Ack:
    """An acknowledgement that took effect, and how long after the episode's first
    confirmation it came (None: the episode was not confirmed before it)."""

    code: str
    source: str
    severity: int
    at_ns: int
    delay_ns: int | None


@dataclass
class Shelf:
    """A shelving: from its record to the next shelving or unshelving of the code; while
    neither is recorded, to its expiry or as_of, whichever is first."""

    code: str
    source: str
    severity: int
    start_ns: int
    until_ns: int
    end_ns: int | None = None

    def stop(self, as_of_ns: int) -> int:
        end = min(as_of_ns, self.until_ns) if self.end_ns is None else self.end_ns
        return max(self.start_ns, end)


@dataclass
class Folded:
    facts: list[Fact] = field(default_factory=list)
    episodes: list[Episode] = field(default_factory=list)
    goals: list[Goal] = field(default_factory=list)
    acks: list[Ack] = field(default_factory=list)
    shelves: list[Shelf] = field(default_factory=list)


def _source(record: LogRecord) -> str:
    event = record.event
    if isinstance(event, FaultReported):
        return event.source_id
    if isinstance(event, FaultCleared):
        return event.actor
    if isinstance(event, FaultConfirmedByTimer):
        return "timer"
    if isinstance(event, ReclassifiedOnStartup):
        return "startup"
    raise AssertionError(f"record {record.seq} ({record.kind}) has no source")


def fold(records: Iterable[LogRecord]) -> Folded:
    """Feed the records one at a time into a fresh Projector; compare each fault's status
    before and after to find the facts and the CONFIRMED episodes."""
    projector = Projector()
    out = Folded()
    previous_report_failed: dict[str, bool] = {}
    activation_times: dict[str, list[int]] = {}
    open_episode: dict[str, Episode] = {}
    first_confirmed: dict[str, int] = {}
    """Per code: the first confirmation of its current episode (since creation/reopening)."""
    open_shelf: dict[str, Shelf] = {}
    for record in records:
        code = record.fault_code
        before = projector.get(code) if code is not None else None
        projector.apply(record)
        if isinstance(record.event, FaultAcknowledged | FaultShelved | FaultUnshelved):
            after = projector.get(code) if code is not None else None
            if before is None or after is None or after == before:
                continue  # refused or no longer fitting: changes nothing, counts nothing
            t = record.occurred_at_ns
            operated = record.event
            if isinstance(operated, FaultAcknowledged):
                confirmed = first_confirmed.get(operated.fault_code)
                delay = None if confirmed is None or t < confirmed else t - confirmed
                out.acks.append(Ack(operated.fault_code, operated.actor, after.severity, t, delay))
                continue
            running = open_shelf.pop(operated.fault_code, None)
            if running is not None:
                running.end_ns = t
            if isinstance(operated, FaultShelved):
                shelf = Shelf(operated.fault_code, operated.actor, after.severity, t,
                              operated.until_ns)
                open_shelf[operated.fault_code] = shelf
                out.shelves.append(shelf)
            continue
        if isinstance(record.event, GoalOutcome):  # counted as it is, touches no fault
            goal = record.event
            out.goals.append(Goal(record.seq, record.occurred_at_ns, goal.action, goal.status,
                                  goal.server_node))
            continue
        if code is None:  # policy_changed
            continue
        after = projector.get(code)
        event = record.event
        if after is None:  # a PASSED for a fault that does not exist: logged, counted
            if isinstance(event, FaultReported):
                previous_report_failed[code] = False
                out.facts.append(Fact(record.seq, record.occurred_at_ns, code, _source(record),
                                      event.severity, failed_report=False, passed_report=True,
                                      activation=False, occurrence=False, confirmation=False,
                                      heal=False, clear=False, chattering=False))
            continue
        was = None if before is None else before.status
        now = after.status
        event = record.event
        t = record.occurred_at_ns
        failed = isinstance(event, FaultReported) and event.event_type is EventType.FAILED
        passed = isinstance(event, FaultReported) and event.event_type is EventType.PASSED

        # FAILED edge: previous stored report of the code not FAILED, first ever, or first
        # after the fault became CLEARED.
        activation = failed and (
            not previous_report_failed.get(code, False)
            or before is None
            or was is FaultStatus.CLEARED
        )
        if isinstance(event, FaultReported):
            previous_report_failed[code] = failed
        chattering = False
        if activation:
            times = activation_times.setdefault(code, [])
            if len(times) >= 2:
                window = [*times[-2:], t]
                chattering = max(window) - min(window) < CHATTER_NS
            times.append(t)

        occurrence = failed and (before is None or was is FaultStatus.CLEARED)
        confirmation = now is FaultStatus.CONFIRMED and was is not FaultStatus.CONFIRMED
        heal = now is FaultStatus.HEALED and was is not FaultStatus.HEALED
        clear = now is FaultStatus.CLEARED and was is not FaultStatus.CLEARED
        fact = Fact(record.seq, t, code, _source(record), after.severity,
                    failed_report=failed, passed_report=passed, activation=activation,
                    occurrence=occurrence, confirmation=confirmation, heal=heal, clear=clear,
                    chattering=chattering)
        out.facts.append(fact)

        if occurrence:
            first_confirmed.pop(code, None)
        if confirmation:
            first_confirmed.setdefault(code, t)
        if was is FaultStatus.CONFIRMED and now is not FaultStatus.CONFIRMED:
            open_episode.pop(code).end_ns = t
        if confirmation:
            assert code not in open_episode
            episode = Episode(code, fact.source, fact.severity, t)
            open_episode[code] = episode
            out.episodes.append(episode)
    return out


# -- periods --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class RefPeriod:
    id: str
    start: datetime
    end: datetime
    name: str | None = None
    """Checked for shift periods only (the page does not name the others)."""
    production_day: date | None = None

    @property
    def start_ns(self) -> int:
        return to_ns(self.start)

    @property
    def end_ns(self) -> int:
        return to_ns(self.end)


@dataclass(frozen=True)
class SimpleShift:
    name: str
    start_hour: int
    end_hour: int


def grid_periods(by: str, zone: ZoneInfo, since: datetime, until: datetime) -> list[RefPeriod]:
    """Local days, hours or 10-minute slots of ``zone`` cut to [since, until).

    Hours and slots are taken on the UTC grid, which is the local grid for zones whose offsets
    are whole hours (UTC, Europe/Berlin; also across DST switches, which happen on the hour):
    the tests use only such zones. The repeated hour of a fall-back night is then two periods
    with the same local id.
    """
    out: list[RefPeriod] = []
    if by == "day":
        day = since.astimezone(zone).date()
        while True:
            start = datetime.combine(day, time(0), tzinfo=zone).astimezone(UTC)
            end = datetime.combine(day + timedelta(days=1), time(0), tzinfo=zone).astimezone(UTC)
            if start >= until:
                break
            if end > since:
                out.append(RefPeriod(day.isoformat(), max(start, since), min(end, until)))
            day += timedelta(days=1)
        return out
    step = timedelta(hours=1) if by == "hour" else timedelta(minutes=10)
    base = since.astimezone(UTC).replace(minute=0, second=0, microsecond=0)
    start = base
    while start < until:
        end = start + step
        if end > since:
            local = start.astimezone(zone)
            assert (local.utcoffset() or timedelta(0)) % timedelta(hours=1) == timedelta(0)
            out.append(RefPeriod(local.strftime("%Y-%m-%dT%H:%M"), max(start, since),
                                 min(end, until)))
        start = end
    return out


def shift_periods(zone: ZoneInfo, shifts: Sequence[SimpleShift], since: datetime,
                  until: datetime) -> list[RefPeriod]:
    """Every-day shifts at whole local hours: instances cropped to [since, until), the gaps
    between them as `unscheduled`."""
    instances: list[tuple[datetime, datetime, str, date]] = []
    day = since.astimezone(zone).date() - timedelta(days=1)
    while day <= until.astimezone(zone).date():
        for shift in shifts:
            start = datetime.combine(day, time(shift.start_hour), tzinfo=zone).astimezone(UTC)
            end_day = day + timedelta(days=1) if shift.end_hour <= shift.start_hour else day
            end = datetime.combine(end_day, time(shift.end_hour), tzinfo=zone).astimezone(UTC)
            instances.append((start, end, shift.name, day))
        day += timedelta(days=1)
    instances.sort()
    out: list[RefPeriod] = []
    cursor = since
    for start, end, name, production_day in instances:
        if end <= since or start >= until:
            continue
        start, end = max(start, since), min(end, until)
        if start > cursor:
            out.append(RefPeriod(UNSCHEDULED, cursor, start, UNSCHEDULED, None))
        out.append(RefPeriod(f"{production_day.isoformat()}/{name}", start, end, name,
                             production_day))
        cursor = end
    if cursor < until:
        out.append(RefPeriod(UNSCHEDULED, cursor, until, UNSCHEDULED, None))
    return out


# -- the figures ----------------------------------------------------------------------------------

def _selected(code: str, codes: Sequence[str] | None) -> bool:
    return codes is None or any(fnmatch.fnmatchcase(code, pattern) for pattern in codes)


def _group_of(item: Fact | Episode | Ack | Shelf, group_by: Sequence[str]
              ) -> tuple[str | int, ...]:
    values: dict[str, str | int] = {"code": item.code, "source": item.source,
                                     "severity": item.severity}
    return tuple(values[key] for key in group_by)


def figures(period: RefPeriod, facts: Sequence[Fact], episodes: Sequence[Episode],
            as_of_ns: int, goals: Sequence[Goal] = (), acks: Sequence[Ack] = (),
            shelves: Sequence[Shelf] = ()) -> dict[str, Any]:
    """Every figure of one row, from the facts, episodes and goals of that row's group."""
    ps, pe = period.start_ns, period.end_ns
    length = pe - ps
    inside = [f for f in facts if ps <= f.at_ns < pe]
    row: dict[str, Any] = {
        "failed_reports": sum(f.failed_report for f in inside),
        "passed_reports": sum(f.passed_report for f in inside),
        "activations": sum(f.activation for f in inside),
        "occurrences": sum(f.occurrence for f in inside),
        "confirmations": sum(f.confirmation for f in inside),
        "heals": sum(f.heal for f in inside),
        "clears": sum(f.clear for f in inside),
        "estops": sum(f.activation for f in inside
                      if fnmatch.fnmatchcase(f.code, ESTOP_GLOB)),
    }
    confirmations = row["confirmations"]

    active_ns = 0
    for episode in episodes:
        overlap = min(episode.end_or(as_of_ns), pe) - max(episode.start_ns, ps)
        active_ns += max(0, overlap)
    row["active_seconds"] = active_ns / NS

    ended = [e for e in episodes if e.end_ns is not None and ps <= e.end_ns < pe]
    row["repairs"] = len(ended)
    durations = [max(0, e.end_ns - e.start_ns) for e in ended if e.end_ns is not None]
    row["mttr_seconds"] = sum(durations) / len(durations) / NS if durations else None
    row["mtbf_seconds"] = length / NS / confirmations if confirmations else None
    row["confirmations_per_10min"] = confirmations / (length / NS / 600)

    flood_windows = 0
    flood_ns = 0
    grid = ps // FLOOD_WINDOW_NS * FLOOD_WINDOW_NS
    while grid < pe:
        ws, we = max(grid, ps), min(grid + FLOOD_WINDOW_NS, pe)
        in_window = sum(1 for f in inside if f.confirmation and ws <= f.at_ns < we)
        if in_window > FLOOD_LIMIT:
            flood_windows += 1
            flood_ns += we - ws
        grid += FLOOD_WINDOW_NS
    row["flood_windows"] = flood_windows
    row["flood_seconds"] = flood_ns / NS
    row["flood_percent"] = flood_ns / length * 100

    row["chattering_codes"] = len({f.code for f in inside if f.chattering})
    row["stale_codes"] = len({
        e.code for e in episodes
        if max(ps, e.start_ns + STALE_NS) < min(pe, e.end_or(as_of_ns))
    })
    per_code: dict[str, int] = {}
    for f in inside:
        if f.confirmation:
            per_code[f.code] = per_code.get(f.code, 0) + 1
    top = sum(sorted(per_code.values(), reverse=True)[:10])
    row["top10_share"] = top / confirmations if confirmations else None
    for status, name in GOAL_COUNTS.items():
        row[name] = sum(1 for g in goals if ps <= g.at_ns < pe and g.status == status)
    acked = [a for a in acks if ps <= a.at_ns < pe]
    row["acknowledgements"] = len(acked)
    delays = [a.delay_ns for a in acked if a.delay_ns is not None]
    row["mtta_seconds"] = sum(delays) / len(delays) / NS if delays else None
    row["shelved_seconds"] = sum(
        max(0, min(pe, shelf.stop(as_of_ns)) - max(ps, shelf.start_ns)) for shelf in shelves) / NS
    return row


def _nonzero(row: dict[str, Any]) -> bool:
    return (any(row[name] for name in (*COUNTS, *GOAL_COUNTS.values(), "acknowledgements"))
            or row["active_seconds"] > 0 or row["repairs"] > 0 or row["stale_codes"] > 0
            or row["shelved_seconds"] > 0)


@dataclass
class Grouped:
    """What one group of rows is counted from."""

    facts: list[Fact] = field(default_factory=list)
    episodes: list[Episode] = field(default_factory=list)
    goals: list[Goal] = field(default_factory=list)
    acks: list[Ack] = field(default_factory=list)
    shelves: list[Shelf] = field(default_factory=list)


@dataclass(frozen=True)
class ExpectedRow:
    period: RefPeriod
    group: dict[str, str | int]
    figures: dict[str, Any]


def expected_rows(folded: Folded, periods: Sequence[RefPeriod], as_of: datetime,
                  codes: Sequence[str] | None = None, group_by: Sequence[str] = ()
                  ) -> list[ExpectedRow]:
    """The rows ``stats`` must return: one per period without ``group_by``; with it, one per
    (period, group) with a non-zero figure, ordered by period start then group key.

    Goal outcomes are not selected by ``codes`` (they have no code). Grouped by ``action``
    (with or without ``source``: the server node), rows hold goal figures only; grouped by
    fault keys only, fault figures only; ungrouped, both."""
    as_of_ns = to_ns(as_of)
    by_action = "action" in group_by
    facts = [] if by_action else [f for f in folded.facts if _selected(f.code, codes)]
    episodes = [] if by_action else [e for e in folded.episodes if _selected(e.code, codes)]
    goals = folded.goals if by_action or not group_by else []
    acks = [] if by_action else [a for a in folded.acks if _selected(a.code, codes)]
    shelves = [] if by_action else [x for x in folded.shelves if _selected(x.code, codes)]
    groups: dict[tuple[str | int, ...], Grouped] = {}
    for f in facts:
        groups.setdefault(_group_of(f, group_by), Grouped()).facts.append(f)
    for e in episodes:
        groups.setdefault(_group_of(e, group_by), Grouped()).episodes.append(e)
    for g in goals:
        values = {"action": g.action, "source": g.server_node}
        goal_key: tuple[str | int, ...] = tuple(values[name] for name in group_by)
        groups.setdefault(goal_key, Grouped()).goals.append(g)
    for a in acks:
        groups.setdefault(_group_of(a, group_by), Grouped()).acks.append(a)
    for x in shelves:
        groups.setdefault(_group_of(x, group_by), Grouped()).shelves.append(x)
    if not group_by:
        groups.setdefault((), Grouped())
    out: list[ExpectedRow] = []
    for period in periods:
        for key in sorted(groups):
            group = groups[key]
            row = figures(period, group.facts, group.episodes, as_of_ns, group.goals,
                          group.acks, group.shelves)
            if group_by and not _nonzero(row):
                continue
            out.append(ExpectedRow(period, dict(zip(group_by, key, strict=True)), row))
    return out


# -- comparing ------------------------------------------------------------------------------------

def _same(actual: Any, expected: Any) -> bool:
    if expected is None or actual is None:
        return actual is None and expected is None
    if isinstance(expected, float):
        return bool(actual == pytest.approx(expected, rel=1e-9, abs=1e-6))
    return bool(actual == expected) and type(actual) is not bool


def differences(actual: Sequence[StatsRow], expected: Sequence[ExpectedRow],
                normalise_id: Callable[[str], str] = lambda period_id: period_id) -> list[str]:
    """Human-readable differences between the rows of ``stats`` and the reference; empty when
    every field of every row agrees. ``normalise_id`` is applied to the ids ``stats`` gave."""
    def key(period_id: str, start: datetime, group: dict[str, str | int]) -> str:
        return f"{period_id} [{start.astimezone(UTC).isoformat()}] {group}"

    problems: list[str] = []
    got_keys = [key(normalise_id(r.period.id), r.period.start, r.group) for r in actual]
    want_keys = [key(r.period.id, r.period.start, r.group) for r in expected]
    if got_keys != want_keys:
        missing = [k for k in want_keys if k not in got_keys]
        extra = [k for k in got_keys if k not in want_keys]
        problems.append(f"rows differ: missing {missing}, unexpected {extra}"
                        if missing or extra else f"row order differs: got {got_keys}")
        return problems
    for got, want in zip(actual, expected, strict=True):
        where = key(want.period.id, want.period.start, want.group)
        if (got.period.start, got.period.end) != (want.period.start, want.period.end):
            problems.append(f"{where}: period {got.period.start}..{got.period.end}, expected "
                            f"{want.period.start}..{want.period.end}")
        if want.period.name is not None and (got.period.name, got.period.production_day) != (
                want.period.name, want.period.production_day):
            problems.append(f"{where}: name/production_day {got.period.name!r}/"
                            f"{got.period.production_day}, expected {want.period.name!r}/"
                            f"{want.period.production_day}")
        for name in FIGURES:
            value = getattr(got, name)
            if not _same(value, want.figures[name]):
                problems.append(f"{where}: {name} = {value!r}, expected "
                                f"{want.figures[name]!r}")
    return problems
