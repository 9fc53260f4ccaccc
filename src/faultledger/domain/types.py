"""The small vocabularies shared by every layer: statuses, severities, report types."""

from __future__ import annotations

from enum import IntEnum, StrEnum


class FaultStatus(StrEnum):
    PREFAILED = "PREFAILED"
    PREPASSED = "PREPASSED"
    CONFIRMED = "CONFIRMED"
    HEALED = "HEALED"
    CLEARED = "CLEARED"


class Severity(IntEnum):
    INFO = 0
    WARN = 1
    ERROR = 2
    CRITICAL = 3


def severity_name(value: int) -> str:
    """``ERROR`` for a known severity, the number for any other (stored as reported)."""
    return Severity(value).name if value in Severity._value2member_map_ else str(value)


class EventType(IntEnum):
    """What a reporter says about a fault; the values are the ROS wire values."""

    FAILED = 0
    PASSED = 1


EVENT_TYPE_NAMES = {member: member.name for member in EventType}
"""EventType -> "FAILED"/"PASSED" (``Enum.name`` is a slow property on Python 3.11)."""
EVENT_TYPES_BY_NAME = {member.name: member for member in EventType}
""""FAILED"/"PASSED" -> EventType: the record decoder's and ``parse_event_type``'s map."""


class NotificationType(StrEnum):
    CONFIRMED = "fault_confirmed"
    UPDATED = "fault_updated"
    CLEARED = "fault_cleared"
    ACKNOWLEDGED = "fault_acknowledged"
    """Ours (not medkit's): the ROS events topic leaves these three out."""
    SHELVED = "fault_shelved"
    UNSHELVED = "fault_unshelved"


MEDKIT_NOTIFICATIONS = frozenset({NotificationType.CONFIRMED, NotificationType.UPDATED,
                                  NotificationType.CLEARED})
"""The event types ros2_medkit's FaultEvent carries; a drop-in peer publishes only these."""


tuple_new = tuple.__new__
"""``tuple_new(SomeNamedTuple, (field, ...))`` builds the NamedTuple from all its fields in
order, as its ``__new__`` does; but that ``__new__`` is interpreted Python, 0.2 µs a call even
from compiled code and 0.5-0.8 µs by keyword. For the few tuples made once per record (a
replay makes millions); docs/performance.md, "Eighth round"."""
