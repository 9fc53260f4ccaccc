"""faultledger: an event-sourced fault manager for ROS 2 robots with a verifiable fault log."""

from faultledger.domain.events import LogRecord
from faultledger.domain.fault import Fault
from faultledger.domain.notifications import Notification
from faultledger.domain.policy import Policy
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import StatsRow
from faultledger.domain.types import EventType, FaultStatus, NotificationType, Severity
from faultledger.errors import FaultLedgerError
from faultledger.service.ledger import FaultLedger, Subscription
from faultledger.service.requests import GoalOutcomeRequest, ReportRequest
from faultledger.service.results import ClearResult, FaultLookup, ReportResult, VerifyReport

__all__ = [
    "ClearResult",
    "EventType",
    "Fault",
    "FaultLedger",
    "FaultLedgerError",
    "FaultLookup",
    "FaultStatus",
    "GoalOutcomeRequest",
    "LogRecord",
    "Notification",
    "NotificationType",
    "Policy",
    "ReportRequest",
    "ReportResult",
    "Severity",
    "ShiftCalendar",
    "StatsRow",
    "Subscription",
    "VerifyReport",
]
