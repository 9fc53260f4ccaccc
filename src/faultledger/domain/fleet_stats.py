"""Statistics of several robots' logs as one row (a line, a site, the fleet): docs/fleet.md,
"Statistics per robot, line and site".

Each robot log's rows are computed at the central by the same code as on the robot; rows of
several logs for one period and group are merged here. Counts and durations add up; the
means are recomputed from the merged counts (MTTR weighted by repairs, MTBF and the
confirmation rate from the period length); the share of time in flood is of robot-time
(``flood_seconds`` / (logs × period)); the top-10 share has no merged value (the codes of
different robots are different alarms), so it is empty. A merged row is complete only when
every log in it is.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

from faultledger.domain.stat_rows import StatsRow

FLEET_KEYS = ("robot", "line", "site")
"""Group keys a fleet central adds to a log's own (docs/fleet.md)."""

_SUMS = ("failed_reports", "passed_reports", "activations", "estops", "occurrences",
         "confirmations", "heals", "clears", "active_seconds", "repairs", "flood_windows",
         "flood_seconds", "chattering_codes", "stale_codes", "aborted_goals", "canceled_goals",
         "succeeded_goals")


def merge(rows: Sequence[StatsRow], group: Mapping[str, str | int]) -> StatsRow:
    """One row for the same period from the rows of several logs."""
    first = rows[0]
    if len(rows) == 1:
        return first if first.group == group else replace(first, group=dict(group))
    sums = {name: sum(getattr(row, name) for row in rows) for name in _SUMS}
    seconds = first.period_seconds
    repaired = [(row.mttr_seconds, row.repairs) for row in rows
                if row.mttr_seconds is not None and row.repairs]
    repairs = sum(count for _, count in repaired)
    confirmations = sums["confirmations"]
    complete = None if all(row.complete is None for row in rows) else all(
        row.complete is not False for row in rows)
    return StatsRow(
        period=first.period, group=dict(group), **sums,
        mttr_seconds=(sum(mean * count for mean, count in repaired) / repairs
                      if repairs else None),
        mtbf_seconds=seconds / confirmations if confirmations else None,
        confirmations_per_10min=confirmations / (seconds / 600) if seconds else 0.0,
        flood_percent=(sums["flood_seconds"] / (len(rows) * seconds) * 100
                       if seconds else 0.0),
        top10_share=None, complete=complete)
