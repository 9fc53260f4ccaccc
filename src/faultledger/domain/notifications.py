"""Which state change is announced on the events stream (SPEC §4.4)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from faultledger.domain.clock import from_ns
from faultledger.domain.fault import Fault
from faultledger.domain.types import FaultStatus, NotificationType


def for_status_change(old: FaultStatus | None, new: FaultStatus) -> NotificationType | None:
    """Announcement for an accepted report or timer move from ``old`` (None: new fault)."""
    if new is FaultStatus.CONFIRMED:
        return NotificationType.UPDATED if old is FaultStatus.CONFIRMED else (
            NotificationType.CONFIRMED
        )
    if new is FaultStatus.HEALED and old is not FaultStatus.HEALED:
        return NotificationType.CLEARED
    return None


@dataclass(frozen=True, slots=True)
class Notification:
    """One announcement: the event type and the full fault state after the change."""

    event_type: NotificationType
    fault: Fault
    timestamp_ns: int
    seq: int

    @property
    def timestamp(self) -> datetime:
        return from_ns(self.timestamp_ns)
