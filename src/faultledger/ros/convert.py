"""Translation between faultledger values and ros2_medkit_msgs / faultledger_msgs messages."""

from __future__ import annotations

import math
from datetime import datetime
from typing import Any

from builtin_interfaces.msg import Time
from faultledger_msgs.msg import LogRecord as LogRecordMsg
from faultledger_msgs.msg import StatsRow as StatsRowMsg
from ros2_medkit_msgs.msg import Fault as FaultMsg
from ros2_medkit_msgs.msg import FaultEvent

from faultledger.domain.clock import NS_PER_SECOND, from_ns, to_ns
from faultledger.domain.events import LogRecord
from faultledger.domain.fault import Fault
from faultledger.domain.integrity import canonical_json
from faultledger.domain.notifications import Notification
from faultledger.domain.stat_rows import COUNT_METRICS, GOAL_METRICS, StatsRow
from faultledger.errors import InvalidInputError
from faultledger.service.requests import GoalOutcomeRequest

NS_PER_MICROSECOND = 1_000
TIME_MAX_SEC = 2**31 - 1
"""builtin_interfaces/Time has an int32 ``sec``: its largest value is 2038-01-19T03:14:07Z."""
TIME_MAX_NS = TIME_MAX_SEC * NS_PER_SECOND + NS_PER_SECOND - 1
"""The largest time a Time can carry (sec=2147483647, nanosec=999999999). The log holds times
up to 2262 (``clock.MAX_NS``); later ones are sent as this one (saturated, docs/ros.md)."""
UINT32_MAX = 2**32 - 1
UINT64_MAX = 2**64 - 1
STATS_FLOATS = ("active_seconds", "confirmations_per_10min", "flood_seconds", "flood_percent",
                "shelved_seconds")
STATS_COUNTS = (*COUNT_METRICS, "estops", "repairs", "flood_windows", "chattering_codes",
                "stale_codes", *GOAL_METRICS, "acknowledgements")
STATS_OPTIONAL = ("mttr_seconds", "mtbf_seconds", "top10_share", "mtta_seconds")
"""Figures that may be undefined (None): NaN in the message."""


def to_time(ns: int) -> Any:
    """A Time for ``ns`` since the epoch, saturated to what a Time can carry: a time after
    2038-01-19T03:14:07.999999999Z is sent as that one (never wrapped to 1901, never an error
    for every caller), one before 1970 as zero."""
    return _set_time(Time(), ns)


def _set_time(stamp: Any, ns: int) -> Any:
    """``stamp`` (a Time) set to ``ns`` as ``to_time`` describes."""
    stamp.sec, stamp.nanosec = divmod(min(max(ns, 0), TIME_MAX_NS), NS_PER_SECOND)
    return stamp


def from_time(stamp: Any) -> int:
    return int(stamp.sec) * NS_PER_SECOND + int(stamp.nanosec)


def request_ns(stamp: Any, name: str) -> int:
    """A Time field of a request as ns since the epoch; zero means "not given". A negative
    ``sec`` or a ``nanosec`` of a second or more is refused (``rclpy`` lets both through)."""
    if int(stamp.sec) < 0:
        raise InvalidInputError(f"{name} must not be before 1970 (sec >= 0), got "
                                f"sec={stamp.sec}")
    if not 0 <= int(stamp.nanosec) < NS_PER_SECOND:
        raise InvalidInputError(f"{name}.nanosec must be below 1,000,000,000, got "
                                f"nanosec={stamp.nanosec}")
    return from_time(stamp)


def _uint(value: int, top: int) -> int:
    """A count for an unsigned field, saturated (a wrapped count would be a wrong number)."""
    return min(max(int(value), 0), top)


def _fault_fields(fault: Fault) -> dict[str, Any]:
    """The Fault message's fields of ``fault`` other than its three times."""
    return {"fault_code": fault.fault_code, "severity": _uint(fault.severity, 255),
            "description": fault.description,
            "occurrence_count": _uint(fault.occurrence_count, UINT32_MAX),
            "status": fault.status.value, "reporting_sources": list(fault.reporting_sources)}


def fault_msg(fault: Fault, into: Any = None) -> Any:
    """A Fault message of ``fault``; ``into``: a Fault message to overwrite instead of a new
    one (each of its fields is set)."""
    if into is None:
        return FaultMsg(**_fault_fields(fault), first_occurred=to_time(fault.first_occurred_ns),
                        last_occurred=to_time(fault.last_occurred_ns),
                        last_passed=to_time(fault.last_passed_ns))
    for name, value in _fault_fields(fault).items():
        setattr(into, name, value)
    _set_time(into.first_occurred, fault.first_occurred_ns)
    _set_time(into.last_occurred, fault.last_occurred_ns)
    _set_time(into.last_passed, fault.last_passed_ns)
    return into


def event_msg(notification: Notification, into: Any = None) -> Any:
    """A FaultEvent of ``notification``; ``into``: a FaultEvent to overwrite instead.

    The events publisher passes the one it published last: ``publish`` converts a message
    to C before it returns, so the next event may reuse it: 3 µs instead of 10 µs for the
    six messages a new event builds (and the defaults rosidl's constructors make of every
    nested field they are given anyway; docs/performance.md, "Tenth round")."""
    if into is None:
        return FaultEvent(event_type=notification.event_type.value,
                          fault=fault_msg(notification.fault),
                          timestamp=to_time(notification.timestamp_ns), auto_cleared_codes=[])
    into.event_type = notification.event_type.value
    fault_msg(notification.fault, into.fault)
    _set_time(into.timestamp, notification.timestamp_ns)
    into.auto_cleared_codes = []
    return into


def record_msg(record: LogRecord) -> Any:
    return LogRecordMsg(
        seq=_uint(record.seq, UINT64_MAX),
        event_id=record.event_id,
        kind=record.kind,
        fault_code=record.fault_code or "",
        source_id=record.source_id or "",
        occurred_at=to_time(record.occurred_at_ns),
        recorded_at=to_time(record.recorded_at_ns),
        schema_version=_uint(record.schema_version, UINT32_MAX),
        payload_json=canonical_json(record.payload),
        hash=record.hash,
    )


def goal_outcome_request(request: Any) -> GoalOutcomeRequest:
    """A ReportGoalOutcome request for ``FaultLedger.record_goal_outcomes``; a zero stamp is
    "now" (the ledger's receive time). A bad stamp raises InvalidInputError (``request_ns``);
    the ledger checks the rest."""
    ns = request_ns(request.stamp, "stamp")
    return GoalOutcomeRequest(request.action, request.goal_id, request.status,
                              request.server_node, from_ns(ns) if ns else None)


def stats_moment(stamp: Any, name: str) -> datetime | None:
    """A GetStatistics Time field as a datetime; None when zero (not given).

    Statistics work at microsecond resolution (datetimes): a stamp with a sub-microsecond part
    is refused rather than rounded, which could move a report across the bound.
    """
    ns = request_ns(stamp, name)
    if ns == 0:
        return None
    if ns % NS_PER_MICROSECOND:
        raise InvalidInputError(
            f"{name} must be a whole number of microseconds (nanosec % 1000 == 0), got "
            f"sec={stamp.sec} nanosec={stamp.nanosec}")
    return from_ns(ns)


def stats_bound(text: str, stamp: Any, name: str) -> datetime | str | None:
    """One bound of GetStatistics: the string ``name`` or the Time ``name``_time, not both."""
    moment = stats_moment(stamp, f"{name}_time")
    if text and moment is not None:
        raise InvalidInputError(f"give {name} or {name}_time, not both")
    return text or moment


def stats_row_msg(row: StatsRow) -> Any:
    period = row.period
    group = row.group
    severity = group.get("severity", -1)
    msg = StatsRowMsg(
        period_id=period.id,
        period_name=period.name,
        production_day="" if period.production_day is None
        else period.production_day.isoformat(),
        start=to_time(to_ns(period.start)),
        end=to_time(to_ns(period.end)),
        code=str(group.get("code", "")),
        source=str(group.get("source", "")),
        severity=min(max(int(severity), -(2**15)), 2**15 - 1),  # int16, saturated
        action=str(group.get("action", "")),
    )
    for name in STATS_COUNTS:
        setattr(msg, name, _uint(getattr(row, name), UINT64_MAX))
    for name in STATS_FLOATS:
        setattr(msg, name, float(getattr(row, name)))
    for name in STATS_OPTIONAL:
        value = getattr(row, name)
        setattr(msg, name, math.nan if value is None else float(value))
    return msg
