"""Figures per period from the statistics projections (definitions: docs/statistics.md).

Two ways in, one way out: ``from_facts`` reads individual facts and episodes (any filter or
grouping, any bounds); ``from_sums`` takes per-period sums of the per-minute table (all
codes, whole minutes) plus the individual facts of a partial first and last minute.
Both fill the same ``_Tally`` per row and finish it with ``_row``.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from faultledger.domain.clock import NS_PER_SECOND, to_ns
from faultledger.domain.shifts import Period
from faultledger.domain.stat_rows import COUNT_METRICS, GOAL_METRIC_OF, GOAL_METRICS, StatsRow
from faultledger.domain.statistics import Episode, GoalFact, StatFact

STALE_AFTER_NS = 24 * 3600 * NS_PER_SECOND
FLOOD_WINDOW_NS = 600 * NS_PER_SECOND
FLOOD_ABOVE = 10
"""A window is in flood with more than this many confirmations (ISA-18.2)."""
TOP = 10
NS_PER_MINUTE = 60 * NS_PER_SECOND
_FLAGS = ("failed", "passed", "activation", "occurrence", "confirmation", "heal", "clear")
_GOAL_INDEX = {status: GOAL_METRICS.index(metric) for status, metric in GOAL_METRIC_OF.items()}

GroupKey = tuple[tuple[str, Any], ...]
Span = tuple[str, int, int | None]
"""(code, start_ns, end_ns or None while open)."""
IsEstop = Callable[[str], bool]
"""Whether a fault code is an e-stop (the config's ``estop_codes``)."""


def _never(_code: str) -> bool:
    return False


class TooManyRows(ValueError):
    """A grouped query made more rows than ``from_facts`` was allowed (``max_rows``)."""


@dataclass(slots=True)
class _Tally:
    counts: list[int] = field(default_factory=lambda: [0] * len(_FLAGS))
    goals: list[int] = field(default_factory=lambda: [0] * len(GOAL_METRICS))
    """Goal outcomes per status, in GOAL_METRICS order."""
    estops: int = 0
    active_ns: int = 0
    repairs: int = 0
    repair_ns: int = 0
    windows: Counter[int] = field(default_factory=Counter)
    """Confirmations per 10-minute grid window."""
    by_code: Counter[str] = field(default_factory=Counter)
    """Confirmations per code."""
    chattering: set[str] = field(default_factory=set)
    stale: set[str] = field(default_factory=set)
    top: int | None = None
    """Confirmations of the top codes, when the store counted them (else from by_code)."""
    chattering_count: int | None = None
    stale_count: int | None = None

    def empty(self) -> bool:
        return not (any(self.counts) or any(self.goals) or self.active_ns or self.repairs
                    or self.chattering or self.stale)

    def add_fact(self, fact: StatFact, is_estop: IsEstop) -> None:
        flags = (fact.failed, fact.passed, fact.activation, fact.occurrence, fact.confirmation,
                 fact.heal, fact.clear)
        self.counts = [a + b for a, b in zip(self.counts, flags, strict=True)]
        if fact.activation and is_estop(fact.code):
            self.estops += 1
        if fact.confirmation:
            self.windows[fact.at_ns // FLOOD_WINDOW_NS] += 1
            self.by_code[fact.code] += 1
        if fact.chatter:
            self.chattering.add(fact.code)

    def add_goal(self, goal: GoalFact) -> None:
        self.goals[_GOAL_INDEX[goal.status]] += 1


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


def _goal_key(group_by: Sequence[str], goal: GoalFact) -> GroupKey:
    values = {"action": goal.action, "source": goal.server_node}
    return tuple((name, values[name]) for name in group_by)


def _episode_end(episode: Episode, as_of_ns: int) -> int:
    return episode.stop_ns(as_of_ns)


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
               group_by: Sequence[str] = (), goals: Iterable[GoalFact] = (),
               is_estop: IsEstop = _never, max_rows: int | None = None) -> list[StatsRow]:
    """Rows from individual facts and episodes (already filtered to the selected codes) and
    goal outcomes; ``is_estop`` picks the activations counted as e-stops. More than
    ``max_rows`` (period, group) pairs with figures raise TooManyRows as soon as they are
    counted, before their rows are made.

    Fault figures and goal figures have different keys: with ``action`` in ``group_by``
    the rows are per action and count goals only (a fault has no action); grouped by fault
    keys only, they count faults only (a goal has no code or severity); ungrouped, both.
    """
    bounds = _Bounds(periods)
    by_action = "action" in group_by
    if by_action:
        facts, episodes = (), ()
    elif group_by:
        goals = ()
    tallies: list[dict[GroupKey, _Tally]] = [{} for _ in periods]
    if not group_by:
        for per_period in tallies:
            per_period[()] = _Tally()

    made = [len(periods) if not group_by else 0]

    def tally_for(i: int, key: GroupKey) -> _Tally:
        found = tallies[i].get(key)
        if found is None:
            made[0] += 1
            if max_rows is not None and made[0] > max_rows:
                raise TooManyRows(f"more than {max_rows} rows")
            found = tallies[i][key] = _Tally()
        return found

    for fact in facts:
        i = bounds.index(fact.at_ns)
        if i is None:
            continue
        tally_for(i, _key(group_by, fact.code, fact.source, fact.severity)).add_fact(
            fact, is_estop)
    for goal in goals:
        i = bounds.index(goal.at_ns)
        if i is not None:
            tally_for(i, _goal_key(group_by, goal)).add_goal(goal)
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
class PeriodSums:
    """What ``from_sums`` needs: figures already added up per period by the store."""

    sums: Sequence[Sequence[int]]
    """Per period: i, the seven counts, starts, Σ starts·minute, Σ start offsets, ends,
    Σ ends·minute, Σ end offsets, repairs, Σ repair ns, aborted, canceled and succeeded
    goals, over the period's whole minutes (periods without minutes may be missing)."""
    busy_windows: Sequence[tuple[int, int, int]]
    """(period i, 10-minute window, confirmations in whole minutes) of the windows that may
    be in flood (the partial minutes' confirmations are added to them)."""
    top_confirmations: Mapping[int, int]
    chattering: Mapping[int, int]
    closed_open_at_start: int
    """Ended episodes that were CONFIRMED at the first period's start."""
    open_spans: Sequence[Span]
    long_spans: Sequence[Span]
    """Ended episodes of 24 h or more that may be stale in the range."""
    partial: Sequence[tuple[int, int]] = ()
    """The ns ranges of a partial first and last minute, which ``sums`` leaves out."""
    partial_facts: Sequence[StatFact] = ()
    partial_goals: Sequence[GoalFact] = ()
    partial_episodes: Sequence[Episode] = ()
    """Episodes starting, or ending by a record, in ``partial`` (each once)."""
    estops: Mapping[int, int] = field(default_factory=dict)
    """Per period i: activations of the e-stop codes (counted by the store: which codes are
    e-stops is the config's choice, so they are not summed per minute)."""


def from_sums(periods: Sequence[Period], data: PeriodSums, as_of_ns: int, *,
              group: Mapping[str, Any] | None = None,
              complete_until_ns: int | None = None) -> list[StatsRow]:
    """Rows over all codes from per-period sums of the per-minute table, plus the facts and
    episode edges of a partial first and last minute. ``group``: the rows' group (a fleet
    central's robot); ``complete_until_ns``: each row is ``complete`` when this reaches its
    period's end (how far a robot has pushed; None: the log's own statistics).

    Active time per period [A, B) is Σ ends − Σ starts + B·open(B) − A·open(A), the sums
    running over the episode edges inside the period (docs/statistics.md).
    """
    if not periods:
        return []
    bounds = _Bounds(periods)
    tallies = [_Tally() for _ in periods]
    edges = [[0, 0, 0, 0] for _ in periods]  # starts, Σ start ns, ends, Σ end ns
    for row in data.sums:
        i = row[0]
        tally = tallies[i]
        tally.counts = list(row[1:8])
        starts, start_minutes, start_offsets, ends, end_minutes, end_offsets = row[8:14]
        edges[i] = [starts, start_minutes * NS_PER_MINUTE + start_offsets,
                    ends, end_minutes * NS_PER_MINUTE + end_offsets]
        tally.repairs = row[14]
        tally.repair_ns = row[15]
        tally.goals = list(row[16:19])
    _add_partial(tallies, edges, bounds, data)
    for i, count in data.estops.items():
        tallies[i].estops = count
    first = bounds.starts[0]
    open_now = data.closed_open_at_start
    for _, start, _ in data.open_spans:
        end = max(start, as_of_ns)
        if start < first <= end:
            open_now += 1
        ending = bounds.index(end)
        if ending is not None:
            edges[ending][2] += 1
            edges[ending][3] += end
    for i, tally in enumerate(tallies):
        starts, start_sum, ends, end_sum = edges[i]
        open_after = open_now + starts - ends
        tally.active_ns = (end_sum - start_sum + bounds.ends[i] * open_after
                           - bounds.starts[i] * open_now)
        open_now = open_after
        tally.top = data.top_confirmations.get(i, 0)
        tally.chattering_count = data.chattering.get(i, 0)
    for i, window, count in data.busy_windows:
        tallies[i].windows[window] += count
    stale = _stale_counts(bounds, (*data.long_spans, *data.open_spans), as_of_ns)
    for tally, count in zip(tallies, stale, strict=True):
        tally.stale_count = count
    return [_row(p, dict(group or {}), tallies[i], bounds, i,
                 None if complete_until_ns is None else complete_until_ns >= bounds.ends[i])
            for i, p in enumerate(periods)]


def _add_partial(tallies: list[_Tally], edges: list[list[int]], bounds: _Bounds,
                 data: PeriodSums) -> None:
    """The figures of the partial first and last minute: counts, flood windows and goals from
    the facts, episode starts, stops and repairs from the episodes."""

    def partial(at_ns: int) -> int | None:
        inside = any(a <= at_ns < b for a, b in data.partial)
        return bounds.index(at_ns) if inside else None

    for fact in data.partial_facts:
        i = bounds.index(fact.at_ns)
        if i is not None:  # (top codes, chattering and e-stops come from the store for
            tallies[i].add_fact(fact, _never)  # every path: see PeriodSums)
    for goal in data.partial_goals:
        i = bounds.index(goal.at_ns)
        if i is not None:
            tallies[i].add_goal(goal)
    for episode in data.partial_episodes:
        i = partial(episode.start_ns)
        if i is not None:
            edges[i][0] += 1
            edges[i][1] += episode.start_ns
        if episode.end_ns is None:
            continue
        stop = episode.stop_ns(episode.end_ns)
        i = partial(stop)
        if i is not None:
            edges[i][2] += 1
            edges[i][3] += stop
        i = partial(episode.end_ns)
        if i is not None:
            tallies[i].repairs += 1
            tallies[i].repair_ns += episode.repair_ns


def _stale_counts(bounds: _Bounds, spans: Iterable[Span], as_of_ns: int) -> list[int]:
    """Distinct stale codes per period: each span's stale part becomes a run of period
    indexes, a code's runs are merged, and a difference array counts them."""
    runs: dict[str, list[tuple[int, int]]] = {}
    for code, start, end in spans:
        stale_from = start + STALE_AFTER_NS
        stop = end if end is not None else max(start, as_of_ns)
        if stale_from >= stop:
            continue
        first = max(0, bisect_right(bounds.starts, stale_from) - 1)
        if bounds.ends[first] <= stale_from:
            first += 1
        last = bisect_left(bounds.starts, stop) - 1
        if first <= last:
            runs.setdefault(code, []).append((first, last))
    delta = [0] * (len(bounds.starts) + 1)
    for code_runs in runs.values():
        code_runs.sort()
        begin, finish = code_runs[0]
        for run_begin, run_finish in code_runs[1:]:
            if run_begin > finish:
                delta[begin] += 1
                delta[finish + 1] -= 1
                begin = run_begin
            finish = max(finish, run_finish)
        delta[begin] += 1
        delta[finish + 1] -= 1
    counts, running = [], 0
    for step in delta[:-1]:
        running += step
        counts.append(running)
    return counts


def _row(period: Period, group: dict[str, Any], tally: _Tally, bounds: _Bounds,
         i: int, complete: bool | None = None) -> StatsRow:
    start, end = bounds.starts[i], bounds.ends[i]
    length_ns = end - start
    seconds = length_ns / NS_PER_SECOND
    counts: dict[str, Any] = dict(zip(COUNT_METRICS, tally.counts, strict=True))
    confirmations = counts["confirmations"]
    flood_ns = 0
    flood_windows = 0
    for window, count in tally.windows.items():
        if count > FLOOD_ABOVE:
            flood_windows += 1
            flood_ns += (min(end, (window + 1) * FLOOD_WINDOW_NS)
                         - max(start, window * FLOOD_WINDOW_NS))
    top = tally.top if tally.top is not None else sum(
        count for _, count in tally.by_code.most_common(TOP))
    chattering = (tally.chattering_count if tally.chattering_count is not None
                  else len(tally.chattering))
    return StatsRow(
        period=period,
        group=group,
        **counts,
        estops=tally.estops,
        active_seconds=tally.active_ns / NS_PER_SECOND,
        repairs=tally.repairs,
        mttr_seconds=tally.repair_ns / tally.repairs / NS_PER_SECOND if tally.repairs else None,
        mtbf_seconds=seconds / confirmations if confirmations else None,
        confirmations_per_10min=confirmations / (seconds / 600) if seconds > 0 else 0.0,
        flood_windows=flood_windows,
        flood_seconds=flood_ns / NS_PER_SECOND,
        flood_percent=100 * flood_ns / length_ns if length_ns > 0 else 0.0,
        chattering_codes=chattering,
        stale_codes=tally.stale_count if tally.stale_count is not None else len(tally.stale),
        top10_share=top / confirmations if confirmations else None,
        **_goal_figures(tally.goals),
        complete=complete,
    )


def _goal_figures(goals: Sequence[int]) -> dict[str, Any]:
    return dict(zip(GOAL_METRICS, goals, strict=True))
