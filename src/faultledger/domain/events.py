"""Event records of the log: small immutable values with a schema version, upcast on read."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from datetime import datetime
from typing import Any, ClassVar

from faultledger.domain.clock import from_ns
from faultledger.domain.types import EventType

SCHEMA_VERSION = 1
"""Version written for every new record; older versions are upcast by ``decode``."""


@dataclass(frozen=True, slots=True)
class FaultReported:
    kind: ClassVar[str] = "fault_reported"
    fault_code: str
    event_type: EventType
    severity: int
    description: str
    source_id: str

    def payload(self) -> dict[str, Any]:
        return {
            "fault_code": self.fault_code,
            "event_type": self.event_type.name,
            "severity": self.severity,
            "description": self.description,
            "source_id": self.source_id,
        }


@dataclass(frozen=True, slots=True)
class FaultCleared:
    kind: ClassVar[str] = "fault_cleared"
    fault_code: str
    actor: str
    reason: str

    @property
    def source_id(self) -> str:
        return self.actor

    def payload(self) -> dict[str, Any]:
        return {"fault_code": self.fault_code, "actor": self.actor, "reason": self.reason}


@dataclass(frozen=True, slots=True)
class FaultConfirmedByTimer:
    kind: ClassVar[str] = "fault_confirmed_by_timer"
    fault_code: str
    after_sec: float

    def payload(self) -> dict[str, Any]:
        return {"fault_code": self.fault_code, "after_sec": self.after_sec}


@dataclass(frozen=True, slots=True)
class PolicyChanged:
    kind: ClassVar[str] = "policy_changed"
    policy: Mapping[str, Any]

    def payload(self) -> dict[str, Any]:
        return {"policy": dict(self.policy)}


@dataclass(frozen=True, slots=True)
class ReclassifiedOnStartup:
    kind: ClassVar[str] = "reclassified_on_startup"
    fault_code: str
    reason: str

    def payload(self) -> dict[str, Any]:
        return {"fault_code": self.fault_code, "reason": self.reason}


DomainEvent = (
    FaultReported | FaultCleared | FaultConfirmedByTimer | PolicyChanged | ReclassifiedOnStartup
)
KINDS = (
    FaultReported.kind,
    FaultCleared.kind,
    FaultConfirmedByTimer.kind,
    PolicyChanged.kind,
    ReclassifiedOnStartup.kind,
)


def fault_code_of(event: DomainEvent) -> str | None:
    return None if isinstance(event, PolicyChanged) else event.fault_code


def source_of(event: DomainEvent) -> str | None:
    if isinstance(event, FaultReported | FaultCleared):
        return event.source_id
    return None


class UnknownRecordError(ValueError):
    """A record this version cannot read: an unknown kind or a newer schema version."""


def _reported(p: Mapping[str, Any]) -> DomainEvent:
    return FaultReported(
        p["fault_code"], EventType[p["event_type"]], p["severity"], p["description"], p["source_id"]
    )


_DECODERS: dict[str, Callable[[Mapping[str, Any]], DomainEvent]] = {
    FaultReported.kind: _reported,
    FaultCleared.kind: lambda p: FaultCleared(p["fault_code"], p["actor"], p["reason"]),
    FaultConfirmedByTimer.kind: lambda p: FaultConfirmedByTimer(p["fault_code"], p["after_sec"]),
    PolicyChanged.kind: lambda p: PolicyChanged(p["policy"]),
    ReclassifiedOnStartup.kind: lambda p: ReclassifiedOnStartup(p["fault_code"], p["reason"]),
}

Upcaster = Callable[[dict[str, Any]], dict[str, Any]]
UPCASTERS: dict[tuple[str, int], Upcaster] = {}
"""(kind, version) -> function turning that version's payload into version + 1's.

Records are never rewritten in place: a v1 record stays v1 on disk and its hash stays valid;
when v2 arrives, register ``UPCASTERS[("fault_reported", 1)] = upcast_v1_v2`` here.
"""


def decode(kind: str, version: int, payload: Mapping[str, Any]) -> DomainEvent:
    if version > SCHEMA_VERSION:
        raise UnknownRecordError(
            f"record of kind {kind!r} has schema version {version}, newer than this "
            f"faultledger reads ({SCHEMA_VERSION}); upgrade faultledger"
        )
    decoder = _DECODERS.get(kind)
    if decoder is None:
        raise UnknownRecordError(f"unknown record kind {kind!r}")
    data = dict(payload)
    while version < SCHEMA_VERSION:
        upcast = UPCASTERS.get((kind, version))
        if upcast is None:
            raise UnknownRecordError(f"no upcaster for {kind!r} version {version}")
        data = upcast(data)
        version += 1
    return decoder(data)


@dataclass(frozen=True, slots=True)
class LogRecord:
    """One durable record of the log, as appended or as read back."""

    seq: int
    event_id: str
    event: DomainEvent
    occurred_at_ns: int
    recorded_at_ns: int
    schema_version: int = SCHEMA_VERSION
    hash: str = ""

    @property
    def kind(self) -> str:
        return self.event.kind

    @property
    def fault_code(self) -> str | None:
        return fault_code_of(self.event)

    @property
    def source_id(self) -> str | None:
        return source_of(self.event)

    @property
    def payload(self) -> dict[str, Any]:
        return self.event.payload()

    @property
    def occurred_at(self) -> datetime:
        return from_ns(self.occurred_at_ns)

    @property
    def recorded_at(self) -> datetime:
        return from_ns(self.recorded_at_ns)
