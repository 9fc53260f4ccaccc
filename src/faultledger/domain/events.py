"""Event records of the log: small immutable values with a schema version, upcast on read.

NamedTuples rather than frozen dataclasses: a replay creates millions of them.
"""

from __future__ import annotations

import uuid
from collections.abc import Callable, Mapping
from datetime import datetime
from typing import Any, NamedTuple

from faultledger.domain.clock import from_ns
from faultledger.domain.types import EVENT_TYPE_NAMES, EVENT_TYPES_BY_NAME, EventType, tuple_new

SCHEMA_VERSION = 1
"""Version written for every new record; older versions are upcast by ``decode``."""


FAULT_REPORTED = "fault_reported"
FAULT_CLEARED = "fault_cleared"
FAULT_CONFIRMED_BY_TIMER = "fault_confirmed_by_timer"
POLICY_CHANGED = "policy_changed"
RECLASSIFIED_ON_STARTUP = "reclassified_on_startup"
GOAL_OUTCOME = "goal_outcome"
LEDGER_IDENTIFIED = "ledger_identified"
FAULT_ACKNOWLEDGED = "fault_acknowledged"
FAULT_SHELVED = "fault_shelved"
FAULT_UNSHELVED = "fault_unshelved"

GOAL_STATUSES = ("SUCCEEDED", "ABORTED", "CANCELED")
"""Terminal statuses of an action goal a goal outcome record can carry."""
GOAL_OUTCOME_NAMESPACE = uuid.UUID("d5f7db67-c1f8-484a-b325-b59fb4c061e4")
"""Fixed namespace of goal outcome event ids (never change it: ids already logged use it)."""


def goal_event_id(action: str, goal_id: str) -> str:
    """The event_id of a goal's outcome: uuid5 over ``action`` and ``goal_id``, so the outcome
    of one goal is recorded once however often it is sent (a republished status array, a
    restarted bridge)."""
    return str(uuid.uuid5(GOAL_OUTCOME_NAMESPACE, f"{action}\n{goal_id}"))


class FaultReported(NamedTuple):
    fault_code: str
    event_type: EventType
    severity: int
    description: str
    source_id: str

    @property
    def kind(self) -> str:
        return FAULT_REPORTED

    def payload(self) -> dict[str, Any]:
        return {
            "fault_code": self.fault_code,
            "event_type": EVENT_TYPE_NAMES[self.event_type],
            "severity": self.severity,
            "description": self.description,
            "source_id": self.source_id,
        }


class FaultCleared(NamedTuple):
    fault_code: str
    actor: str
    reason: str

    @property
    def source_id(self) -> str:
        return self.actor

    @property
    def kind(self) -> str:
        return FAULT_CLEARED

    def payload(self) -> dict[str, Any]:
        return {"fault_code": self.fault_code, "actor": self.actor, "reason": self.reason}


class FaultConfirmedByTimer(NamedTuple):
    fault_code: str
    after_sec: float

    @property
    def kind(self) -> str:
        return FAULT_CONFIRMED_BY_TIMER

    def payload(self) -> dict[str, Any]:
        return {"fault_code": self.fault_code, "after_sec": self.after_sec}


class PolicyChanged(NamedTuple):
    policy: Mapping[str, Any]

    @property
    def kind(self) -> str:
        return POLICY_CHANGED

    def payload(self) -> dict[str, Any]:
        return {"policy": dict(self.policy)}


class ReclassifiedOnStartup(NamedTuple):
    fault_code: str
    reason: str

    @property
    def kind(self) -> str:
        return RECLASSIFIED_ON_STARTUP

    def payload(self) -> dict[str, Any]:
        return {"fault_code": self.fault_code, "reason": self.reason}


class GoalOutcome(NamedTuple):
    """The terminal status of one action goal (SPEC §3, §8): counted per goal, so aborts are
    exact even while the action's fault stays latched. Changes no fault."""

    action: str
    goal_id: str
    status: str
    """One of GOAL_STATUSES."""
    server_node: str

    @property
    def source_id(self) -> str:
        return self.server_node

    @property
    def kind(self) -> str:
        return GOAL_OUTCOME

    def payload(self) -> dict[str, Any]:
        return {"action": self.action, "goal_id": self.goal_id, "status": self.status,
                "server_node": self.server_node}


class LedgerIdentified(NamedTuple):
    """Which robot's log this is (``robot_id``) and which log (``ledger_id``, a UUID made
    with it): written once, by the first writer, before its first other record. A fleet's
    central keeps one hash chain per ledger_id; later copies never change it."""

    robot_id: str
    ledger_id: str

    @property
    def kind(self) -> str:
        return LEDGER_IDENTIFIED

    def payload(self) -> dict[str, Any]:
        return {"robot_id": self.robot_id, "ledger_id": self.ledger_id}


class FaultAcknowledged(NamedTuple):
    """An operator has seen episode ``episode`` of a fault (docs/semantics.md, "The
    operator's day"). Changes no status; the next episode needs its own acknowledgement."""

    fault_code: str
    actor: str
    note: str
    episode: int
    """The fault's ``occurrence_count`` when it was acknowledged."""

    @property
    def source_id(self) -> str:
        return self.actor

    @property
    def kind(self) -> str:
        return FAULT_ACKNOWLEDGED

    def payload(self) -> dict[str, Any]:
        return {"fault_code": self.fault_code, "actor": self.actor, "note": self.note,
                "episode": self.episode}


class FaultShelved(NamedTuple):
    """A known nuisance hidden until ``until_ns`` (ISA-18.2 shelving): status and counts go
    on as before; lists, the dashboard and alerts leave it out."""

    fault_code: str
    actor: str
    reason: str
    until_ns: int

    @property
    def source_id(self) -> str:
        return self.actor

    @property
    def kind(self) -> str:
        return FAULT_SHELVED

    def payload(self) -> dict[str, Any]:
        return {"fault_code": self.fault_code, "actor": self.actor, "reason": self.reason,
                "until_ns": self.until_ns}


class FaultUnshelved(NamedTuple):
    """The end of a shelving: by an operator, or by the serving process when it expired
    (actor ``timer``, stamped with the expiry time, so a replay ends it at the same time)."""

    fault_code: str
    actor: str
    reason: str

    @property
    def source_id(self) -> str:
        return self.actor

    @property
    def kind(self) -> str:
        return FAULT_UNSHELVED

    def payload(self) -> dict[str, Any]:
        return {"fault_code": self.fault_code, "actor": self.actor, "reason": self.reason}


OperatorEvent = FaultAcknowledged | FaultShelved | FaultUnshelved
"""Records of what people did about a fault, beside what the robot reported."""

DomainEvent = (
    FaultReported | FaultCleared | FaultConfirmedByTimer | PolicyChanged | ReclassifiedOnStartup
    | GoalOutcome | LedgerIdentified | FaultAcknowledged | FaultShelved | FaultUnshelved
)
KINDS = (
    FAULT_REPORTED,
    FAULT_CLEARED,
    FAULT_CONFIRMED_BY_TIMER,
    POLICY_CHANGED,
    RECLASSIFIED_ON_STARTUP,
    GOAL_OUTCOME,
    LEDGER_IDENTIFIED,
    FAULT_ACKNOWLEDGED,
    FAULT_SHELVED,
    FAULT_UNSHELVED,
)


def fault_code_of(event: DomainEvent) -> str | None:
    """The fault a record concerns; None for a policy change, a goal outcome and the log's
    identity (stored as NULL, so no code filter ever matches them)."""
    return (None if isinstance(event, PolicyChanged | GoalOutcome | LedgerIdentified)
            else event.fault_code)


def source_of(event: DomainEvent) -> str | None:
    if isinstance(event, FaultReported | FaultCleared | GoalOutcome | FaultAcknowledged
                  | FaultShelved | FaultUnshelved):
        return event.source_id
    return None


class UnknownRecordError(ValueError):
    """A record this version cannot read: an unknown kind or a newer schema version."""


def _reported(p: Mapping[str, Any]) -> DomainEvent:
    event: FaultReported = tuple_new(FaultReported, (  # nine records in ten: see tuple_new
        p["fault_code"], EVENT_TYPES_BY_NAME[p["event_type"]], p["severity"], p["description"],
        p["source_id"]))
    return event


_DECODERS: dict[str, Callable[[Mapping[str, Any]], DomainEvent]] = {
    FAULT_REPORTED: _reported,
    FAULT_CLEARED: lambda p: FaultCleared(p["fault_code"], p["actor"], p["reason"]),
    FAULT_CONFIRMED_BY_TIMER: lambda p: FaultConfirmedByTimer(p["fault_code"], p["after_sec"]),
    POLICY_CHANGED: lambda p: PolicyChanged(p["policy"]),
    RECLASSIFIED_ON_STARTUP: lambda p: ReclassifiedOnStartup(p["fault_code"], p["reason"]),
    GOAL_OUTCOME: lambda p: GoalOutcome(p["action"], p["goal_id"], p["status"],
                                        p["server_node"]),
    LEDGER_IDENTIFIED: lambda p: LedgerIdentified(p["robot_id"], p["ledger_id"]),
    FAULT_ACKNOWLEDGED: lambda p: FaultAcknowledged(p["fault_code"], p["actor"], p["note"],
                                                    p["episode"]),
    FAULT_SHELVED: lambda p: FaultShelved(p["fault_code"], p["actor"], p["reason"],
                                          p["until_ns"]),
    FAULT_UNSHELVED: lambda p: FaultUnshelved(p["fault_code"], p["actor"], p["reason"]),
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
    data = payload
    while version < SCHEMA_VERSION:
        upcast = UPCASTERS.get((kind, version))
        if upcast is None:
            raise UnknownRecordError(f"no upcaster for {kind!r} version {version}")
        data = upcast(dict(data))
        version += 1
    return decoder(data)


class LogRecord(NamedTuple):
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
