"""Translation between faultledger values and ros2_medkit_msgs / faultledger_msgs messages."""

from __future__ import annotations

from typing import Any

from builtin_interfaces.msg import Time
from faultledger_msgs.msg import LogRecord as LogRecordMsg
from ros2_medkit_msgs.msg import Fault as FaultMsg
from ros2_medkit_msgs.msg import FaultEvent

from faultledger.domain.clock import NS_PER_SECOND
from faultledger.domain.events import LogRecord
from faultledger.domain.fault import Fault
from faultledger.domain.integrity import canonical_json
from faultledger.domain.notifications import Notification


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
