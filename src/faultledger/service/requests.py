"""Inputs of the service API that travel in batches (``FaultLedger.report_many``,
``FaultLedger.record_goal_outcomes``)."""

from __future__ import annotations

from datetime import datetime
from typing import NamedTuple


class ReportRequest(NamedTuple):
    """The arguments of ``FaultLedger.report``, as one value."""

    fault_code: str
    event_type: str | int
    severity: int = 0
    description: str = ""
    source_id: str = ""
    at: datetime | None = None
    event_id: str | None = None


class GoalOutcomeRequest(NamedTuple):
    """The arguments of ``FaultLedger.record_goal_outcome``, as one value."""

    action: str
    goal_id: str
    status: str
    """SUCCEEDED, ABORTED or CANCELED."""
    server_node: str = ""
    at: datetime | None = None
