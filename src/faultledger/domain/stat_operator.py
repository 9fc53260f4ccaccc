"""The operator's figures per period (docs/statistics.md, "The operator's day"):
``acknowledgements``, ``mtta_seconds`` and ``shelved_seconds``, added to the rows either
statistics path made. Acknowledgements and shelvings are few, so both paths read them whole
for the range and this one function counts them: the two paths cannot differ on them."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace

from faultledger.domain.clock import NS_PER_SECOND, to_ns
from faultledger.domain.shifts import Period
from faultledger.domain.stat_compute import GroupKey, _Bounds, _key, _sortable
from faultledger.domain.stat_rows import StatsRow
from faultledger.domain.statistics import ACK, OperatorFact


@dataclass(slots=True)
class _Tally:
    acknowledgements: int = 0
    timed: int = 0
    """Acknowledgements of an episode confirmed before them: the ones MTTA averages."""
    delay_ns: int = 0
    shelved_ns: int = 0

    def into(self, row: StatsRow) -> StatsRow:
        return replace(row, acknowledgements=self.acknowledgements,
                       mtta_seconds=self.delay_ns / self.timed / NS_PER_SECOND if self.timed
                       else None,
                       shelved_seconds=self.shelved_ns / NS_PER_SECOND)


def add_operator_figures(rows: list[StatsRow], periods: Sequence[Period],
                         facts: Iterable[OperatorFact], as_of_ns: int,
                         group_by: Sequence[str] = (),
                         selects: Callable[[str], bool] = lambda _code: True) -> list[StatsRow]:
    """``rows`` with the operator's figures of the facts whose code ``selects`` takes. Grouped,
    a group with only operator figures gets a row of its own (in its period, in key order);
    grouped by ``action`` nothing changes (an acknowledgement has no action)."""
    if not periods or "action" in group_by:
        return rows
    bounds = _Bounds(periods)
    tallies: dict[tuple[int, GroupKey], _Tally] = {}

    def tally(i: int, fact: OperatorFact) -> _Tally:
        key = (i, _key(group_by, fact.code, fact.source, fact.severity))
        found = tallies.get(key)
        if found is None:
            found = tallies[key] = _Tally()
        return found

    for fact in facts:
        if not selects(fact.code):
            continue
        if fact.kind == ACK:
            i = bounds.index(fact.at_ns)
            if i is not None:
                counted = tally(i, fact)
                counted.acknowledgements += 1
                if fact.delay_ns is not None:
                    counted.timed += 1
                    counted.delay_ns += fact.delay_ns
            continue
        for i, overlap in bounds.overlaps(fact.at_ns, fact.stop_ns(as_of_ns)):
            tally(i, fact).shelved_ns += overlap
    if not tallies:
        return rows
    index = {to_ns(period.start): i for i, period in enumerate(periods)}
    merged: list[list[StatsRow]] = [[] for _ in periods]
    for row in rows:
        i = index[to_ns(row.period.start)]
        key = tuple((name, row.group[name]) for name in group_by)
        found = tallies.pop((i, key), None)
        merged[i].append(row if found is None else found.into(row))
    for (i, key), found in tallies.items():  # groups with operator figures only
        merged[i].append(found.into(StatsRow(period=periods[i], group=dict(key))))
    return [row for per_period in merged
            for row in sorted(per_period, key=lambda r: _sortable(
                tuple((name, r.group[name]) for name in group_by)))]
