"""``FaultLedger.stats``: arguments checked, the cheapest exact path chosen, rows computed."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from fnmatch import fnmatchcase

from sqlalchemy import Connection

from faultledger.domain import stat_compute, validation
from faultledger.domain.clock import MAX_TIME, MIN_TIME, NS_PER_SECOND, from_ns, to_ns
from faultledger.domain.periods import PERIOD_KINDS, parse_bound, periods
from faultledger.domain.shifts import Period, ShiftCalendar
from faultledger.domain.stat_operator import add_operator_figures
from faultledger.domain.stat_rows import DEFAULT_ESTOP_CODES, FAULT_KEYS, GROUP_KEYS, StatsRow
from faultledger.domain.statistics import Episode, GoalFact, StatFact
from faultledger.errors import InvalidInputError
from faultledger.store import stat_tables
from faultledger.store.database import Database

DEFAULT_SPAN = timedelta(hours=24)
MAX_PERIODS = 60_000
"""Refuse ranges cut into more periods than that (a year of 10-minute slots is 52,560): a
bigger answer helps nobody and would hold up a serving process. docs/statistics.md."""
MAX_PATTERNS = 256
"""Most code patterns one query may name."""
MAX_PATTERN_LENGTH = 256
_STEP_NS = {"10min": 600 * NS_PER_SECOND, "hour": 3600 * NS_PER_SECOND,
            "day": 86_400 * NS_PER_SECOND}
NS_PER_MINUTE = 60 * NS_PER_SECOND
NS_PER_MICROSECOND = 1_000


@dataclass(frozen=True, slots=True)
class StatsBudget:
    """The most work one ``stats`` call may do: the HTTP API sets one (docs/http.md,
    "Limits"); without one only MAX_PERIODS applies. Each limit is checked before the work
    it bounds: periods before any is cut, records by counting index entries before any row
    is read, rows as the fold makes them."""

    rows: int
    """Rows of the answer: its periods, or (period, group) pairs with figures."""
    records: int
    """Facts, CONFIRMED episodes and goal outcomes read by a query the per-minute sums
    cannot answer (``code`` or ``group_by`` given, or period edges off whole minutes)."""
    rows_setting: str = ""
    records_setting: str = ""
    """Names of the settings behind the limits, shown in a refusal."""


def open_end_ns(as_of_ns: int) -> int:
    """Where a range with no ``until`` ends: just after ``as_of`` (the start of the next
    microsecond, as a datetime can hold it), so what happened at ``as_of`` itself, also a
    report stamped with the very datetime given as ``as_of``, is counted."""
    return min((as_of_ns // NS_PER_MICROSECOND + 1) * NS_PER_MICROSECOND, to_ns(MAX_TIME))


class StatsQuery:
    """Validated arguments of one ``stats`` call: every problem is an InvalidInputError naming
    it, found before any period is cut or any row read."""

    def __init__(self, by: str, since: datetime | str | None, until: datetime | str | None,
                 codes: Sequence[str] | None, group_by: Sequence[str],
                 calendar: ShiftCalendar, as_of: datetime | None,
                 estop_codes: Sequence[str] = DEFAULT_ESTOP_CODES,
                 budget: StatsBudget | None = None) -> None:
        if not isinstance(by, str) or by not in PERIOD_KINDS:
            raise InvalidInputError(f"by must be one of {', '.join(PERIOD_KINDS)}, got "
                                    f"{validation.shown(by)}")
        self.by = by
        self.group_by = _group_by(group_by)
        self.codes = _codes(codes)
        self.estop_codes = tuple(estop_codes)
        if as_of is None:
            self.as_of_ns = time.time_ns()
        else:
            _check_time(as_of, "as_of")
            self.as_of_ns = to_ns(as_of)
        until_at = (_bound(until, calendar, upper=True) if until is not None
                    else from_ns(open_end_ns(self.as_of_ns)))
        since_at = (_bound(since, calendar, upper=False) if since is not None
                    else max(until_at - DEFAULT_SPAN, MIN_TIME))
        if since_at >= until_at:
            raise InvalidInputError(f"since ({since_at.isoformat()}) must be before until "
                                    f"({until_at.isoformat()})")
        self.since_ns, self.until_ns = to_ns(since_at), to_ns(until_at)
        self.budget = budget
        most, setting = MAX_PERIODS, ""
        if budget is not None and budget.rows < MAX_PERIODS:
            most, setting = budget.rows, budget.rows_setting
        estimate = _estimate(by, since_at, until_at, calendar)
        if estimate > most * 1.1:  # clearly too many: refused before cutting any
            raise InvalidInputError(_too_many(f"about {estimate:,}", by, most, setting))
        self.periods: list[Period] = periods(by, since_at, until_at, calendar, most)
        if len(self.periods) > most:
            raise InvalidInputError(_too_many(f"more than {most:,}", by, most, setting))

    def selects(self, code: str) -> bool:
        return self.codes is None or any(fnmatchcase(code, glob) for glob in self.codes)

    def is_estop(self, code: str) -> bool:
        return any(fnmatchcase(code, glob) for glob in self.estop_codes)

    def inner_minute_aligned(self) -> bool:
        """Every period edge but ``since`` and ``until`` lies on a whole minute (the minute
        table serves the whole minutes; a partial first and last minute is read from facts)."""
        return all(to_ns(p.start) % NS_PER_MINUTE == 0 for p in self.periods[1:])


def _estimate(by: str, since: datetime, until: datetime, calendar: ShiftCalendar) -> int:
    """Periods in [since, until), from the range's length (clock periods) or from the number
    of shift periods in its first week: cheap, so a huge range costs nothing to refuse."""
    span = to_ns(until) - to_ns(since)
    step = _STEP_NS.get(by)
    if step is not None:
        return span // step
    week = timedelta(days=7)
    if span <= 2 * week.total_seconds() * NS_PER_SECOND:
        return 0  # cut exactly below
    per_week = len(periods(by, since, since + week, calendar, MAX_PERIODS))
    return int(span / (week.total_seconds() * NS_PER_SECOND) * per_week)


def _too_many(count: str, by: str, most: int = MAX_PERIODS, setting: str = "") -> str:
    named = f" ({setting})" if setting else ""
    return (f"the range holds {count} periods of {by}, the limit is {most:,}{named}: narrow "
            "the range or choose longer periods")


def _too_many_records(budget: StatsBudget) -> str:
    named = f" ({budget.records_setting})" if budget.records_setting else ""
    return (f"this query would read more than {budget.records:,} records (facts, episodes "
            f"and goal outcomes in the range), the limit is {budget.records:,}{named}: narrow "
            "the range or select fewer codes; without code and group_by, on periods of whole "
            "minutes, the figures come from per-minute sums and read few records")


def _too_many_rows(budget: StatsBudget, by: str, periods: int) -> str:
    named = f" ({budget.rows_setting})" if budget.rows_setting else ""
    return (f"this query makes more than {budget.rows:,} rows ({periods:,} periods of {by} "
            f"times its groups), the limit is {budget.rows:,}{named}: narrow the range, "
            "choose longer periods, select fewer codes or group by fewer keys")


def _group_by(group_by: Sequence[str]) -> tuple[str, ...]:
    wanted = (group_by,) if isinstance(group_by, str) else group_by
    if not isinstance(wanted, Sequence) or len(wanted) > len(GROUP_KEYS):
        raise InvalidInputError(f"group_by takes distinct names from {', '.join(GROUP_KEYS)}")
    names = tuple(wanted)
    if any(not isinstance(g, str) or g not in GROUP_KEYS for g in names) or (
            len(set(names)) != len(names)):
        raise InvalidInputError(f"group_by takes distinct names from {', '.join(GROUP_KEYS)}, "
                                f"got {validation.shown(list(names))}")
    if "action" in names and any(key in names for key in FAULT_KEYS):
        raise InvalidInputError("group_by action combines only with source: a goal outcome "
                                "has no code or severity")
    return names


def _codes(codes: Sequence[str] | None) -> tuple[str, ...] | None:
    if codes is None:
        return None
    if isinstance(codes, str):
        raise InvalidInputError("codes is a list of glob patterns, not one string")
    if not isinstance(codes, Sequence) or len(codes) > MAX_PATTERNS:
        raise InvalidInputError(f"codes takes at most {MAX_PATTERNS} glob patterns")
    for code in codes:
        if not isinstance(code, str) or not code:
            raise InvalidInputError("codes must be non-empty glob patterns")
        problem = validation.text_error("a code pattern", code, MAX_PATTERN_LENGTH)
        if problem:
            raise InvalidInputError(problem)
    return tuple(codes)


def estop_globs(codes: Sequence[str]) -> tuple[str, ...]:
    """The e-stop code globs, checked like a query's ``codes`` (at least one)."""
    checked = _codes(codes)
    if not checked:
        raise InvalidInputError("estop_codes needs at least one glob pattern "
                                f"(default {', '.join(DEFAULT_ESTOP_CODES)})")
    return checked


def _check_time(moment: object, name: str) -> None:
    problem = validation.time_error(name, moment)
    if problem:
        raise InvalidInputError(problem)


def _bound(value: datetime | str, calendar: ShiftCalendar, *, upper: bool) -> datetime:
    name = "until" if upper else "since"
    if isinstance(value, str):
        if len(value) > 64:
            raise InvalidInputError(f"{name}: expected a date, a date-time or a shift id, got "
                                    f"{validation.shown(value)}")
        try:
            value = parse_bound(value, calendar, upper=upper)
        except ValueError as error:
            raise InvalidInputError(f"{name}: {error}") from None
    _check_time(value, name)
    return value


def compute(db: Database, query: StatsQuery) -> list[StatsRow]:
    """Per-minute sums when the question allows it (all codes, no grouping, inner period
    edges on whole minutes), else the individual facts of the selected codes; both exact.

    Goal outcomes have no fault code: ``codes`` does not select them (docs/statistics.md).
    """
    if not query.periods:
        return []
    with db.reading() as conn:
        rows = _compute(conn, query)
        [operated] = stat_tables.operator_facts(stat_tables.Logs(conn), query.since_ns,
                                                query.until_ns)
    return add_operator_figures(rows, query.periods, operated, query.as_of_ns, query.group_by,
                                query.selects)


def _compute(conn: Connection, query: StatsQuery) -> list[StatsRow]:
    """The fault and goal figures (``compute`` adds the operator's)."""
    budget = query.budget
    if from_sums(query):
        [sums] = _sums(stat_tables.Logs(conn), query)
        return stat_compute.from_sums(query.periods, sums, query.as_of_ns)
    read_goals = not query.group_by or "action" in query.group_by
    read_faults = "action" not in query.group_by
    only = None
    if read_faults and query.codes is not None:
        only = [code for code in stat_tables.codes(conn) if query.selects(code)]
    if budget is not None and stat_tables.count_records(
            conn, query.since_ns, query.until_ns, only, faults=read_faults,
            goals=read_goals, most=budget.records) > budget.records:
        raise InvalidInputError(_too_many_records(budget))
    goals = []
    if read_goals:
        goals = stat_tables.goals(conn, query.since_ns, query.until_ns)
    facts, episodes = [], []
    if read_faults:
        facts = stat_tables.facts(conn, query.since_ns, query.until_ns, only)
        episodes = stat_tables.episodes(conn, query.since_ns, query.until_ns, only)
    try:
        return stat_compute.from_facts(query.periods, facts, episodes, query.as_of_ns,
                                       query.group_by, goals, query.is_estop,
                                       None if budget is None else budget.rows)
    except stat_compute.TooManyRows:
        assert budget is not None
        raise InvalidInputError(_too_many_rows(budget, query.by,
                                               len(query.periods))) from None


def from_sums(query: StatsQuery) -> bool:
    """Whether the per-minute and per-hour sums answer ``query`` (all codes, no grouping,
    inner period edges on whole minutes)."""
    return query.codes is None and not query.group_by and query.inner_minute_aligned()


def compute_in_schemas(db: Database, schemas: Sequence[str], query: StatsQuery,
                       groups: Sequence[Mapping[str, str | int]],
                       complete_until_ns: Sequence[int]) -> list[list[StatsRow]]:
    """``compute`` of many logs of one PostgreSQL database, each in its own schema (a fleet
    central's robot logs), where the sums answer (``from_sums``): each read is one
    statement over every log, in one snapshot. The rows of each log, in ``schemas`` order,
    are those ``compute`` gives for it alone, in the log's group (``groups``) and marked
    complete up to where the log is complete (``complete_until_ns``)."""
    if not from_sums(query):
        raise ValueError("compute_in_schemas answers from the sums only")
    if not query.periods:
        return [[] for _ in schemas]
    with db.reading() as conn:
        found = _sums(stat_tables.Logs(conn, schemas), query)
        operated = stat_tables.operator_facts(stat_tables.Logs(conn, schemas), query.since_ns,
                                              query.until_ns)
    return [add_operator_figures(
        stat_compute.from_sums(query.periods, sums, query.as_of_ns, group=group,
                               complete_until_ns=complete), query.periods, facts, query.as_of_ns)
        for sums, group, complete, facts in zip(found, groups, complete_until_ns, operated,
                                                strict=True)]


def _whole_minutes(since_ns: int, until_ns: int) -> tuple[int, int, list[tuple[int, int]]]:
    """The whole minutes [a, b) of [since, until) in ns, and the partial rest as ns ranges."""
    first = -(-since_ns // NS_PER_MINUTE) * NS_PER_MINUTE
    last = until_ns // NS_PER_MINUTE * NS_PER_MINUTE
    if first >= last:
        return first, first, [(since_ns, until_ns)]
    return first, last, [(a, b) for a, b in ((since_ns, first), (last, until_ns)) if a < b]


def _sums(logs: stat_tables.Logs, query: StatsQuery) -> list[stat_compute.PeriodSums]:
    edges = [(to_ns(p.start), to_ns(p.end)) for p in query.periods]
    first, last, partial = _whole_minutes(query.since_ns, query.until_ns)
    minutes = []
    for a, b in edges:  # inner edges are whole minutes (``inner_minute_aligned``)
        begin = max(a, first)
        minutes.append((begin // NS_PER_MINUTE, max(begin, min(b, last)) // NS_PER_MINUTE))
    count = len(logs)
    facts: list[list[StatFact]] = [[] for _ in range(count)]
    goals: list[list[GoalFact]] = [[] for _ in range(count)]
    episodes: list[dict[int, Episode]] = [{} for _ in range(count)]
    for a, b in partial:
        for log_facts, more in zip(facts, stat_tables.facts_of(logs, a, b), strict=True):
            log_facts.extend(more)
        for found_goals, more_goals in zip(goals, stat_tables.goals_of(logs, a, b),
                                           strict=True):
            found_goals.extend(more_goals)
        for by_start, edge in zip(episodes, stat_tables.edge_episodes(logs, a, b),
                                  strict=True):
            by_start.update((e.start_seq, e) for e in edge)
    estop_codes = sorted({code for log_codes in stat_tables.codes_of(logs)
                          for code in log_codes if query.is_estop(code)})
    columns = zip(
        stat_tables.period_sums(logs, minutes),
        stat_tables.top_confirmations(logs, edges, stat_compute.TOP),
        stat_tables.chattering(logs, edges),
        stat_tables.closed_open_at(logs, query.since_ns),
        stat_tables.open_spans(logs),
        stat_tables.long_spans(logs, query.since_ns, query.until_ns,
                               stat_compute.STALE_AFTER_NS),
        stat_tables.estops(logs, edges, estop_codes),
        facts, goals, episodes, strict=True)
    made: list[stat_compute.PeriodSums] = []
    busy = _busy_windows(logs, minutes, facts)
    for (sums, top, chattering, closed_open, open_spans, long_spans, estops, log_facts,
         log_goals, log_episodes), windows in zip(columns, busy, strict=True):
        made.append(stat_compute.PeriodSums(
            sums=sums, busy_windows=windows, top_confirmations=top, chattering=chattering,
            closed_open_at_start=closed_open, open_spans=open_spans, long_spans=long_spans,
            partial=partial, partial_facts=log_facts, partial_goals=log_goals,
            partial_episodes=list(log_episodes.values()), estops=estops))
    return made


def _busy_windows(logs: stat_tables.Logs, minutes: list[tuple[int, int]],
                  facts: list[list[StatFact]]) -> list[list[tuple[int, int, int]]]:
    """Per log, the windows that may be in flood: more confirmations in whole minutes than
    the flood limit less those of the log's partial minutes (so the one read serves every
    log, it asks for the lowest such threshold and each log keeps what it needs)."""
    partial = [sum(f.confirmation for f in log_facts) for log_facts in facts]
    above = [stat_compute.FLOOD_ABOVE - n for n in partial]
    found = stat_tables.busy_windows(logs, minutes,
                                     stat_compute.FLOOD_WINDOW_NS // NS_PER_MINUTE, min(above))
    return [[w for w in windows if w[2] > least] for windows, least in zip(found, above,
                                                                           strict=True)]
