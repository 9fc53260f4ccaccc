"""Figures per period from the statistics projections (definitions: docs/statistics.md).

Two ways in, one way out: ``from_facts`` reads individual facts and episodes (any filter or
grouping, any bounds); ``from_minutes`` adds up per-minute sums (all codes, minute bounds).
Both fill the same ``_Tally`` per row and finish it with ``_row``.
"""

from __future__ import annotations

from bisect import bisect_right
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from faultledger.domain.clock import NS_PER_SECOND, to_ns
from faultledger.domain.shifts import Period
from faultledger.domain.stat_rows import COUNT_METRICS, StatsRow
from faultledger.domain.statistics import Episode, StatFact

STALE_AFTER_NS = 24 * 3600 * NS_PER_SECOND
FLOOD_WINDOW_NS = 600 * NS_PER_SECOND
FLOOD_ABOVE = 10
"""A window is in flood with more than this many confirmations (ISA-18.2)."""
TOP = 10
NS_PER_MINUTE = 60 * NS_PER_SECOND
_FLAGS = ("failed", "passed", "activation", "occurrence", "confirmation", "heal", "clear")

GroupKey = tuple[tuple[str, Any], ...]


@dataclass(slots=True)
class _Tally:
    counts: list[int] = field(default_factory=lambda: [0] * len(_FLAGS))
    active_ns: int = 0
    repairs: int = 0
    repair_ns: int = 0
    windows: Counter[int] = field(default_factory=Counter)
    """Confirmations per 10-minute grid window."""
    by_code: Counter[str] = field(default_factory=Counter)
    """Confirmations per code."""
    chattering: set[str] = field(default_factory=set)
    stale: set[str] = field(default_factory=set)

    def empty(self) -> bool:
        return not (any(self.counts) or self.active_ns or self.repairs or self.chattering
                    or self.stale)


class _Bounds:
    """Period edges in ns, for finding the periods a time or an interval falls in."""

    def __init__(self, periods: Sequence[Period]) -> None:
        self.periods = periods
        self.starts = [to_ns(p.start) for p in periods]
        self.ends = [to_ns(p.end) for p in periods]

    def index(self, at_ns: int) -> int | None:
        i = bisect_right(self.starts, at_ns) - 1
        return i if i >= 0 and at_ns < self.ends[i] else None

    def overlaps(self, begin: int, end: int) -> Iterable[tuple[int, int]]:
        """(period index, overlap ns) for each period [begin, end) overlaps."""
        i = max(0, bisect_right(self.starts, begin) - 1)
        while i < len(self.starts) and self.starts[i] < end:
            overlap = min(end, self.ends[i]) - max(begin, self.starts[i])
            if overlap > 0:
                yield i, overlap
            i += 1


def _key(group_by: Sequence[str], code: str, source: str, severity: int) -> GroupKey:
    values = {"code": code, "source": source, "severity": severity}
    return tuple((name, values[name]) for name in group_by)


def _episode_end(episode: Episode, as_of_ns: int) -> int:
    return episode.end_ns if episode.end_ns is not None else max(episode.start_ns, as_of_ns)


def _add_episode(tally: _Tally, bounds: _Bounds, i: int, episode: Episode, end: int) -> None:
    """Repairs and staleness of one episode in period ``i``."""
    if episode.end_ns is not None and bounds.index(episode.end_ns) == i:
        tally.repairs += 1
        tally.repair_ns += episode.repair_ns
    stale_from = episode.start_ns + STALE_AFTER_NS
    if max(stale_from, bounds.starts[i]) < min(end, bounds.ends[i]):
        tally.stale.add(episode.code)


def from_facts(periods: Sequence[Period], facts: Iterable[StatFact],
               episodes: Iterable[Episode], as_of_ns: int,
               group_by: Sequence[str] = ()) -> list[StatsRow]:
    """Rows from individual facts and episodes (already filtered to the selected codes)."""
    bounds = _Bounds(periods)
    tallies: list[dict[GroupKey, _Tally]] = [{} for _ in periods]
    if not group_by:
        for per_period in tallies:
            per_period[()] = _Tally()

    def tally_for(i: int, key: GroupKey) -> _Tally:
        found = tallies[i].get(key)
        if found is None:
            found = tallies[i][key] = _Tally()
        return found

    for fact in facts:
        i = bounds.index(fact.at_ns)
        if i is None:
            continue
        tally = tally_for(i, _key(group_by, fact.code, fact.source, fact.severity))
        flags = (fact.failed, fact.passed, fact.activation, fact.occurrence, fact.confirmation,
                 fact.heal, fact.clear)
        tally.counts = [a + b for a, b in zip(tally.counts, flags, strict=True)]
        if fact.confirmation:
            tally.windows[fact.at_ns // FLOOD_WINDOW_NS] += 1
            tally.by_code[fact.code] += 1
        if fact.chatter:
            tally.chattering.add(fact.code)
    for episode in episodes:
        end = _episode_end(episode, as_of_ns)
        key = _key(group_by, episode.code, episode.source, episode.severity)
        touched: dict[int, int] = dict(bounds.overlaps(episode.start_ns, end))
        if episode.end_ns is not None:
            repaired_in = bounds.index(episode.end_ns)
            if repaired_in is not None:
                touched.setdefault(repaired_in, 0)
        for i in sorted(touched):
            tally = tally_for(i, key)
            tally.active_ns += touched.get(i, 0)
            _add_episode(tally, bounds, i, episode, end)
    return [_row(periods[i], dict(key), tally, bounds, i)
            for i in range(len(periods))
            for key, tally in sorted(tallies[i].items(), key=lambda kv: _sortable(kv[0]))
            if not group_by or not tally.empty()]


def _sortable(key: GroupKey) -> tuple[tuple[str, str], ...]:
    return tuple((name, f"{value:>4}" if isinstance(value, int) else value)
                 for name, value in key)


@dataclass(frozen=True, slots=True)
class MinuteInputs:
    """What ``from_minutes`` needs besides the minute sums."""

    minutes: Sequence[Sequence[int]]
    """(minute, failed, passed, activation, occurrence, confirmation, heal, clear, starts,
    start_offset_ns, ends, end_offset_ns, repair_ns), minute ascending."""
    closed_open_at_start: int
    """Ended episodes that were CONFIRMED at the first period's start."""
    open_episodes: Sequence[Episode]
    long_episodes: Sequence[Episode]
    chatter: Sequence[tuple[int, str]]
    confirmations: Sequence[tuple[int, str]]


def from_minutes(periods: Sequence[Period], data: MinuteInputs, as_of_ns: int) -> list[StatsRow]:
    """Rows over all codes from per-minute sums; every period edge must be a whole minute.

    Active time per period [A, B) is Σ ends − Σ starts + B·open(B) − A·open(A), where the
    sums run over episode edges inside the period (docs/statistics.md).
    """
    bounds = _Bounds(periods)
    if not periods:
        return []
    tallies = [_Tally() for _ in periods]
    edge_sums = [[0, 0, 0, 0] for _ in periods]  # starts, Σstart, ends, Σend
    minute_starts = [s // NS_PER_MINUTE for s in bounds.starts]
    for row in data.minutes:
        minute = row[0]
        i = bisect_right(minute_starts, minute) - 1
        if i < 0 or minute * NS_PER_MINUTE >= bounds.ends[i]:
            continue
        tally = tallies[i]
        counts = row[1:8]
        tally.counts = [a + b for a, b in zip(tally.counts, counts, strict=True)]
        if counts[4]:
            tally.windows[minute * NS_PER_MINUTE // FLOOD_WINDOW_NS] += counts[4]
        base = minute * NS_PER_MINUTE
        sums = edge_sums[i]
        sums[0] += row[8]
        sums[1] += row[8] * base + row[9]
        sums[2] += row[10]
        sums[3] += row[10] * base + row[11]
        tally.repairs += row[10]
        tally.repair_ns += row[12]
    first = bounds.starts[0]
    open_now = data.closed_open_at_start
    for episode in data.open_episodes:
        end = _episode_end(episode, as_of_ns)
        if episode.start_ns < first <= end:
            open_now += 1
        ending = bounds.index(end)
        if ending is not None:
            edge_sums[ending][2] += 1
            edge_sums[ending][3] += end
    for i, tally in enumerate(tallies):
        starts, start_sum, ends, end_sum = edge_sums[i]
        open_after = open_now + starts - ends
        tally.active_ns = end_sum - start_sum + bounds.ends[i] * open_after - (
            bounds.starts[i] * open_now)
        open_now = open_after
    for at_ns, code in data.chatter:
        j = bounds.index(at_ns)
        if j is not None:
            tallies[j].chattering.add(code)
    for at_ns, code in data.confirmations:
        j = bounds.index(at_ns)
        if j is not None:
            tallies[j].by_code[code] += 1
    for episode in (*data.long_episodes, *data.open_episodes):
        end = _episode_end(episode, as_of_ns)
        for j, _ in bounds.overlaps(episode.start_ns + STALE_AFTER_NS, end):
            tallies[j].stale.add(episode.code)
    return [_row(p, {}, tallies[i], bounds, i) for i, p in enumerate(periods)]


def _row(period: Period, group: dict[str, Any], tally: _Tally, bounds: _Bounds,
         i: int) -> StatsRow:
    start, end = bounds.starts[i], bounds.ends[i]
    length_ns = end - start
    seconds = length_ns / NS_PER_SECOND
    counts = dict(zip(COUNT_METRICS, tally.counts, strict=True))
    confirmations = counts["confirmations"]
    flood_ns = 0
    flood_windows = 0
    for window, count in tally.windows.items():
        if count > FLOOD_ABOVE:
            flood_windows += 1
            flood_ns += (min(end, (window + 1) * FLOOD_WINDOW_NS)
                         - max(start, window * FLOOD_WINDOW_NS))
    top = sum(count for _, count in tally.by_code.most_common(TOP))
    return StatsRow(
        period=period,
        group=group,
        **counts,
        active_seconds=tally.active_ns / NS_PER_SECOND,
        repairs=tally.repairs,
        mttr_seconds=tally.repair_ns / tally.repairs / NS_PER_SECOND if tally.repairs else None,
        mtbf_seconds=seconds / confirmations if confirmations else None,
        confirmations_per_10min=confirmations / (seconds / 600) if seconds > 0 else 0.0,
        flood_windows=flood_windows,
        flood_seconds=flood_ns / NS_PER_SECOND,
        flood_percent=100 * flood_ns / length_ns if length_ns > 0 else 0.0,
        chattering_codes=len(tally.chattering),
        stale_codes=len(tally.stale),
        top10_share=top / confirmations if confirmations else None,
    )
