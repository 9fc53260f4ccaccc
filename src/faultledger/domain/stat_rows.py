"""The answer of ``FaultLedger.stats``: one row per period and group (docs/statistics.md)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from faultledger.domain.shifts import Period

GROUP_KEYS = ("code", "source", "severity", "action")
"""What ``group_by`` may name. ``action`` groups goal outcomes (docs/statistics.md, Groups):
it combines with ``source`` (the action server's node) only."""
FAULT_KEYS = ("code", "severity")
"""Group keys only faults have; ``action`` only goal outcomes have."""

DEFAULT_ESTOP_CODES = ("HW_*_EMERGENCY_STOP",)
"""What an e-stop is unless the config's ``estop_codes`` says otherwise: the codes the
hardware status bridge raises for an emergency stop (docs/bridges/hardware_status.md)."""

COUNT_METRICS = ("failed_reports", "passed_reports", "activations", "occurrences",
                 "confirmations", "heals", "clears")
GOAL_METRICS = ("aborted_goals", "canceled_goals", "succeeded_goals")
"""Goal outcome records per terminal status (never fault edges)."""
GOAL_METRIC_OF = {"ABORTED": "aborted_goals", "CANCELED": "canceled_goals",
                  "SUCCEEDED": "succeeded_goals"}


@dataclass(frozen=True, slots=True)
class StatsRow:
    """Figures of one period for one group (``group`` is empty without ``group_by``).

    Optional figures are None where they are undefined (no confirmations, no repairs).
    """

    period: Period
    group: dict[str, str | int] = field(default_factory=dict)
    failed_reports: int = 0
    passed_reports: int = 0
    activations: int = 0
    estops: int = 0
    """Activations of the e-stop codes (``estop_codes``): e-stop presses."""
    occurrences: int = 0
    confirmations: int = 0
    heals: int = 0
    clears: int = 0
    active_seconds: float = 0.0
    repairs: int = 0
    mttr_seconds: float | None = None
    mtbf_seconds: float | None = None
    confirmations_per_10min: float = 0.0
    flood_windows: int = 0
    flood_seconds: float = 0.0
    flood_percent: float = 0.0
    chattering_codes: int = 0
    stale_codes: int = 0
    top10_share: float | None = None
    aborted_goals: int = 0
    canceled_goals: int = 0
    succeeded_goals: int = 0
    acknowledgements: int = 0
    """Acknowledgement records (docs/statistics.md, "The operator's day")."""
    mtta_seconds: float | None = None
    """Mean time to acknowledge: first confirmation of the episode → its acknowledgement,
    over the acknowledgements in the period of episodes confirmed before them."""
    shelved_seconds: float = 0.0
    """Time the row's faults spent shelved in the period."""
    complete: bool | None = None
    """At a fleet central: False while a robot in the row has not pushed past the period's
    end (provisional: more records may come); None for a log's own statistics."""

    @property
    def period_seconds(self) -> float:
        return (self.period.end - self.period.start).total_seconds()

    def as_dict(self) -> dict[str, Any]:
        """Flat, JSON-ready: period fields first, then the group keys, then the figures."""
        figures = asdict(self)
        figures.pop("period")
        group = figures.pop("group")
        if figures["complete"] is None:
            figures.pop("complete")
        period = self.period
        return {
            "period": period.id,
            "period_name": period.name,
            "production_day": None if period.production_day is None
            else period.production_day.isoformat(),
            "start": period.start.isoformat(),
            "end": period.end.isoformat(),
            **group,
            **figures,
        }
