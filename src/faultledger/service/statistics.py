"""``FaultLedger.stats``: arguments checked, the cheapest exact path chosen, rows computed."""

from __future__ import annotations

import time
from collections.abc import Sequence
from datetime import datetime, timedelta
from fnmatch import fnmatchcase

from sqlalchemy import Connection

from faultledger.domain import stat_compute, validation
from faultledger.domain.clock import MIN_TIME, NS_PER_SECOND, from_ns, to_ns
from faultledger.domain.periods import PERIOD_KINDS, parse_bound, periods
from faultledger.domain.shifts import Period, ShiftCalendar
from faultledger.domain.stat_rows import GROUP_KEYS, StatsRow
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


class StatsQuery:
    """Validated arguments of one ``stats`` call: every problem is an InvalidInputError naming
    it, found before any period is cut or any row read."""

    def __init__(self, by: str, since: datetime | str | None, until: datetime | str | None,
                 codes: Sequence[str] | None, group_by: Sequence[str],
                 calendar: ShiftCalendar, as_of: datetime | None) -> None:
        if not isinstance(by, str) or by not in PERIOD_KINDS:
            raise InvalidInputError(f"by must be one of {', '.join(PERIOD_KINDS)}, got "
                                    f"{validation.shown(by)}")
        self.group_by = _group_by(group_by)
        self.codes = _codes(codes)
        if as_of is None:
            self.as_of_ns = time.time_ns()
        else:
            _check_time(as_of, "as_of")
            self.as_of_ns = to_ns(as_of)
        until_at = (_bound(until, calendar, upper=True) if until is not None
                    else from_ns(self.as_of_ns - self.as_of_ns % (60 * NS_PER_SECOND)))
        since_at = (_bound(since, calendar, upper=False) if since is not None
                    else max(until_at - DEFAULT_SPAN, MIN_TIME))
        if since_at >= until_at:
            raise InvalidInputError(f"since ({since_at.isoformat()}) must be before until "
                                    f"({until_at.isoformat()})")
        self.since_ns, self.until_ns = to_ns(since_at), to_ns(until_at)
        step = _STEP_NS.get(by)
        if step is not None and (self.until_ns - self.since_ns) // step > MAX_PERIODS:
            raise InvalidInputError(_too_many(f"about {(self.until_ns - self.since_ns) // step:,}",
                                              by))
        self.periods: list[Period] = periods(by, since_at, until_at, calendar, MAX_PERIODS)
        if len(self.periods) > MAX_PERIODS:
            raise InvalidInputError(_too_many(f"more than {MAX_PERIODS:,}", by))

    def selects(self, code: str) -> bool:
        return self.codes is None or any(fnmatchcase(code, glob) for glob in self.codes)

    def minute_aligned(self) -> bool:
        minute = 60 * NS_PER_SECOND
        return self.since_ns % minute == 0 and self.until_ns % minute == 0 and all(
            to_ns(p.start) % minute == 0 for p in self.periods)


def _too_many(count: str, by: str) -> str:
    return (f"the range holds {count} periods of {by}, the limit is {MAX_PERIODS:,}: narrow the "
            "range or choose longer periods")


def _group_by(group_by: Sequence[str]) -> tuple[str, ...]:
    wanted = (group_by,) if isinstance(group_by, str) else group_by
    if not isinstance(wanted, Sequence) or len(wanted) > len(GROUP_KEYS):
        raise InvalidInputError(f"group_by takes distinct names from {', '.join(GROUP_KEYS)}")
    names = tuple(wanted)
    if any(not isinstance(g, str) or g not in GROUP_KEYS for g in names) or (
            len(set(names)) != len(names)):
        raise InvalidInputError(f"group_by takes distinct names from {', '.join(GROUP_KEYS)}, "
                                f"got {validation.shown(list(names))}")
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
    """Per-minute sums when the question allows it (all codes, no grouping, whole minutes),
    else the individual facts of the selected codes; both are exact."""
    if not query.periods:
        return []
    with db.reading() as conn:
        if query.codes is None and not query.group_by and query.minute_aligned():
            return stat_compute.from_sums(query.periods, _sums(conn, query), query.as_of_ns)
        only = None
        if query.codes is not None:
            only = [code for code in stat_tables.codes(conn) if query.selects(code)]
        facts = stat_tables.facts(conn, query.since_ns, query.until_ns, only)
        episodes = stat_tables.episodes(conn, query.since_ns, query.until_ns, only)
    return stat_compute.from_facts(query.periods, facts, episodes, query.as_of_ns,
                                   query.group_by)


def _sums(conn: Connection, query: StatsQuery) -> stat_compute.PeriodSums:
    minute = 60 * NS_PER_SECOND
    edges = [(to_ns(p.start), to_ns(p.end)) for p in query.periods]
    minutes = [(a // minute, b // minute) for a, b in edges]
    return stat_compute.PeriodSums(
        sums=stat_tables.period_sums(conn, minutes),
        busy_windows=stat_tables.busy_windows(
            conn, minutes, stat_compute.FLOOD_WINDOW_NS // minute, stat_compute.FLOOD_ABOVE),
        top_confirmations=stat_tables.top_confirmations(conn, edges, stat_compute.TOP),
        chattering=stat_tables.chattering(conn, edges),
        closed_open_at_start=stat_tables.closed_open_at(conn, query.since_ns),
        open_spans=stat_tables.open_spans(conn),
        long_spans=stat_tables.long_spans(conn, query.since_ns, query.until_ns,
                                          stat_compute.STALE_AFTER_NS),
    )
