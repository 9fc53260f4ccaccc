"""faultledger: an event-sourced fault manager for ROS 2 robots with a verifiable fault log.

Everything a caller of ``FaultLedger`` needs is importable from here: the ledger, the values
its methods take and return, and every exception it may raise (all are ``FaultLedgerError``;
``reason`` tells them apart by kind, as the results' ``reason`` does).
"""

from faultledger import compiled as _compiled

_compiled.drop_stale()  # before any compiled module is imported (a checkout only)

from faultledger.domain.events import LogRecord
from faultledger.domain.fault import Fault
from faultledger.domain.identity import LedgerIdentity
from faultledger.domain.notifications import Notification
from faultledger.domain.policy import Policy, SourceOverride
from faultledger.domain.projector import Transition
from faultledger.domain.shifts import Period, ShiftCalendar, ShiftInstance
from faultledger.domain.stat_rows import StatsRow
from faultledger.domain.types import EventType, FaultStatus, NotificationType, Severity
from faultledger.errors import (
    ConfigError,
    DamagedDatabaseError,
    DatabaseFullError,
    DatabaseLockedError,
    DatabaseReadOnlyError,
    FaultLedgerError,
    IdentityMismatchError,
    InternalError,
    InvalidInputError,
    LedgerClosedError,
    NotADatabaseError,
    Reason,
    SchemaOutdatedError,
    SchemaTooNewError,
    StoreError,
    WriteConflictError,
)
from faultledger.service.ledger import FaultLedger, Restored, Subscription
from faultledger.service.requests import GoalOutcomeRequest, ReportRequest
from faultledger.service.results import (
    ClearResult,
    Downtime,
    EntityLookup,
    FaultLookup,
    OperatorResult,
    ReportResult,
    VerifyReport,
)

__all__ = [
    "ClearResult",
    "ConfigError",
    "DamagedDatabaseError",
    "DatabaseFullError",
    "DatabaseLockedError",
    "DatabaseReadOnlyError",
    "Downtime",
    "EntityLookup",
    "EventType",
    "Fault",
    "FaultLedger",
    "FaultLedgerError",
    "FaultLookup",
    "FaultStatus",
    "GoalOutcomeRequest",
    "IdentityMismatchError",
    "InternalError",
    "InvalidInputError",
    "LedgerClosedError",
    "LedgerIdentity",
    "LogRecord",
    "NotADatabaseError",
    "Notification",
    "NotificationType",
    "OperatorResult",
    "Period",
    "Policy",
    "Reason",
    "ReportRequest",
    "ReportResult",
    "Restored",
    "SchemaOutdatedError",
    "SchemaTooNewError",
    "Severity",
    "ShiftCalendar",
    "ShiftInstance",
    "SourceOverride",
    "StatsRow",
    "StoreError",
    "Subscription",
    "Transition",
    "VerifyReport",
    "WriteConflictError",
]
