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
from faultledger.domain.stat_rows import COUNT_METRICS, StatsRow
from faultledger.errors import InvalidInputError

NS_PER_MICROSECOND = 1_000
STATS_FLOATS = ("active_seconds", "confirmations_per_10min", "flood_seconds", "flood_percent")
STATS_COUNTS = (*COUNT_METRICS, "repairs", "flood_windows", "chattering_codes", "stale_codes")
STATS_OPTIONAL = ("mttr_seconds", "mtbf_seconds", "top10_share")
"""Figures that may be undefined (None): NaN in the message."""


def to_time(ns: int) -> Any:
    seconds, nanoseconds = divmod(ns, NS_PER_SECOND)
    return Time(sec=seconds, nanosec=nanoseconds)


def from_time(stamp: Any) -> int:
    return int(stamp.sec) * NS_PER_SECOND + int(stamp.nanosec)


def fault_msg(fault: Fault) -> Any:
    return FaultMsg(
        fault_code=fault.fault_code,
        severity=fault.severity,
        description=fault.description,
        first_occurred=to_time(fault.first_occurred_ns),
        last_occurred=to_time(fault.last_occurred_ns),
        last_passed=to_time(fault.last_passed_ns),
        occurrence_count=fault.occurrence_count,
        status=fault.status.value,
        reporting_sources=list(fault.reporting_sources),
    )


def event_msg(notification: Notification) -> Any:
    return FaultEvent(
        event_type=notification.event_type.value,
        fault=fault_msg(notification.fault),
        timestamp=to_time(notification.timestamp_ns),
        auto_cleared_codes=[],
    )


def record_msg(record: LogRecord) -> Any:
    return LogRecordMsg(
        seq=record.seq,
        event_id=record.event_id,
        kind=record.kind,
        fault_code=record.fault_code or "",
        source_id=record.source_id or "",
        occurred_at=to_time(record.occurred_at_ns),
        recorded_at=to_time(record.recorded_at_ns),
        schema_version=record.schema_version,
        payload_json=canonical_json(record.payload),
        hash=record.hash,
    )


def stats_moment(stamp: Any, name: str) -> datetime | None:
    """A GetStatistics Time field as a datetime; None when zero (not given).

    Statistics work at microsecond resolution (datetimes): a stamp with a sub-microsecond part
    is refused rather than rounded, which could move a report across the bound.
    """
    ns = from_time(stamp)
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
        severity=int(severity),
    )
    for name in STATS_COUNTS:
        setattr(msg, name, int(getattr(row, name)))
    for name in STATS_FLOATS:
        setattr(msg, name, float(getattr(row, name)))
    for name in STATS_OPTIONAL:
        value = getattr(row, name)
        setattr(msg, name, math.nan if value is None else float(value))
    return msg
