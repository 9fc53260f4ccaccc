"""``FaultLedger.stats``: arguments checked, the cheapest exact path chosen, rows computed."""

from __future__ import annotations

import time
from collections.abc import Sequence
from datetime import datetime, timedelta
from fnmatch import fnmatchcase

from sqlalchemy import Connection

from faultledger.domain import stat_compute
from faultledger.domain.clock import NS_PER_SECOND, from_ns, to_ns
from faultledger.domain.periods import PERIOD_KINDS, parse_bound, periods
from faultledger.domain.shifts import Period, ShiftCalendar
from faultledger.domain.stat_rows import GROUP_KEYS, StatsRow
from faultledger.errors import InvalidInputError
from faultledger.store import stat_tables
from faultledger.store.database import Database

DEFAULT_SPAN = timedelta(hours=24)
MAX_PERIODS = 60_000
"""Refuse ranges cut into more periods than that (a year of 10-minute slots, ~3 s): a
bigger answer helps nobody and would hold up a serving process."""


class StatsQuery:
    """Validated arguments of one ``stats`` call."""

    def __init__(self, by: str, since: datetime | str | None, until: datetime | str | None,
                 codes: Sequence[str] | None, group_by: Sequence[str],
                 calendar: ShiftCalendar, as_of: datetime | None) -> None:
        if by not in PERIOD_KINDS:
            raise InvalidInputError(f"by must be one of {', '.join(PERIOD_KINDS)}, got {by!r}")
        unknown = [g for g in group_by if g not in GROUP_KEYS]
        if unknown or len(set(group_by)) != len(group_by):
            raise InvalidInputError(f"group_by takes distinct names from "
                                    f"{', '.join(GROUP_KEYS)}, got {list(group_by)}")
        if isinstance(codes, str):
            raise InvalidInputError("codes is a list of glob patterns, not one string")
        if codes is not None and not all(isinstance(c, str) and c for c in codes):
            raise InvalidInputError("codes must be non-empty glob patterns")
        self.as_of_ns = time.time_ns() if as_of is None else _aware_ns(as_of, "as_of")
        until_at = (_bound(until, calendar, upper=True) if until is not None
                    else from_ns(self.as_of_ns - self.as_of_ns % (60 * NS_PER_SECOND)))
        since_at = (_bound(since, calendar, upper=False) if since is not None
                    else until_at - DEFAULT_SPAN)
        if since_at >= until_at:
            raise InvalidInputError(f"since ({since_at.isoformat()}) must be before until "
                                    f"({until_at.isoformat()})")
        self.periods: list[Period] = periods(by, since_at, until_at, calendar)
        if len(self.periods) > MAX_PERIODS:
            raise InvalidInputError(f"{len(self.periods)} periods of {by}: narrow the range")
        self.since_ns, self.until_ns = to_ns(since_at), to_ns(until_at)
        self.codes = None if codes is None else tuple(codes)
        self.group_by = tuple(group_by)

    def selects(self, code: str) -> bool:
        return self.codes is None or any(fnmatchcase(code, glob) for glob in self.codes)

    def minute_aligned(self) -> bool:
        minute = 60 * NS_PER_SECOND
        return self.since_ns % minute == 0 and self.until_ns % minute == 0 and all(
            to_ns(p.start) % minute == 0 for p in self.periods)


def _aware_ns(moment: datetime, name: str) -> int:
    try:
        return to_ns(moment)
    except (ValueError, TypeError, AttributeError):
        raise InvalidInputError(f"{name} must be a timezone-aware datetime") from None


def _bound(value: datetime | str, calendar: ShiftCalendar, *, upper: bool) -> datetime:
    name = "until" if upper else "since"
    if isinstance(value, str):
        try:
            return parse_bound(value, calendar, upper=upper)
        except ValueError as error:
            raise InvalidInputError(f"{name}: {error}") from None
    _aware_ns(value, name)
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
