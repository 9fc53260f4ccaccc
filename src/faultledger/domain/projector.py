"""The fold of log records into fault state, status transitions and announcements."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import NamedTuple

from faultledger.domain import debounce
from faultledger.domain.events import (
    DomainEvent,
    FaultAcknowledged,
    FaultCleared,
    FaultConfirmedByTimer,
    FaultReported,
    FaultShelved,
    FaultUnshelved,
    GoalOutcome,
    LedgerIdentified,
    LogRecord,
    PolicyChanged,
    ReclassifiedOnStartup,
)
from faultledger.domain.fault import Acknowledgement, Fault, Shelving
from faultledger.domain.identity import LedgerIdentity
from faultledger.domain.notifications import for_status_change
from faultledger.domain.policy import Policy
from faultledger.domain.statistics import StatsFold
from faultledger.domain.transition import Transition
from faultledger.domain.types import EVENT_TYPE_NAMES, FaultStatus, NotificationType, tuple_new

__all__ = ["Effect", "Projector", "Transition"]


class Effect(NamedTuple):
    """What one record did: the fault after it (None: untouched), and its announcement."""

    fault: Fault | None = None
    transition: Transition | None = None
    notification: NotificationType | None = None


_NOTHING = Effect()


class Projector:
    """Fault state after the records applied so far; deterministic: it reads only the records.

    ``stage()`` starts a group of applications that ``commit()`` keeps or ``rollback()`` undoes,
    so a failed database commit leaves the in-memory state as it was.
    """

    def __init__(
        self,
        faults: Mapping[str, Fault] | None = None,
        policy: Policy | None = None,
        seq: int = 0,
        policy_recorded: bool = False,
        policy_seq: int = 0,
        stats: StatsFold | None = None,
        identity: LedgerIdentity | None = None,
        identity_seq: int = 0,
    ) -> None:
        self.stats = stats
        """The statistics fold, when this projector feeds the persisted projections."""
        self._faults: dict[str, Fault] = dict(faults or {})
        self._staged: dict[str, Fault] | None = None
        self._saved: tuple[Policy, int, bool, int, LedgerIdentity | None, int, int] | None = None
        self.policy = policy or Policy()
        self.policy_recorded = policy_recorded
        self.policy_seq = policy_seq
        self.seq = seq
        self.committed_seq = seq
        """``seq`` as readers may see it: staged records are not included until ``commit``,
        which sets it after the faults, so a reader that sees a seq sees its faults."""
        self.identity = identity
        """The log's identity: its first ``ledger_identified`` record (None before one)."""
        self.identity_seq = identity_seq
        """The seq of that record (0: none yet)."""
        self.committed_identity = identity
        """``identity`` as readers may see it (like ``committed_seq``)."""
        self.ignored_identities: list[int] = []
        """Seqs of later ``ledger_identified`` records: no writer writes one, so ``verify``
        names them; the first one stays the log's identity."""

    # -- reading -----------------------------------------------------------------------------
    def get(self, fault_code: str) -> Fault | None:
        if self._staged is not None:
            staged = self._staged.get(fault_code)
            if staged is not None:
                return staged
        return self._faults.get(fault_code)

    def get_committed(self, fault_code: str) -> Fault | None:
        return self._faults.get(fault_code)

    def committed(self) -> list[Fault]:
        """Snapshot of committed faults (safe to call from another thread)."""
        return list(self._faults.values())

    def snapshot(self) -> dict[str, Fault]:
        merged = dict(self._faults)
        if self._staged:
            merged.update(self._staged)
        return merged

    def overdue_for_timer(self, now_ns: int) -> list[str]:
        after = self.policy.auto_confirm_after_sec
        return sorted(
            code
            for code, fault in self.snapshot().items()
            if debounce.is_overdue(fault, after, now_ns)
        )

    def to_reclassify(self, policy: Policy) -> list[str]:
        return sorted(
            code
            for code, fault in self.snapshot().items()
            if debounce.reclassify_on_startup(fault, policy)
        )

    # -- staging -----------------------------------------------------------------------------
    def stage(self) -> None:
        if self.stats is not None:
            self.stats.stage()
        self._staged = {}
        self._saved = (self.policy, self.seq, self.policy_recorded, self.policy_seq,
                       self.identity, self.identity_seq, len(self.ignored_identities))

    def staged_faults(self) -> list[Fault]:
        return list((self._staged or {}).values())

    def commit(self) -> None:
        if self.stats is not None:
            self.stats.commit()
        if self._staged:
            self._faults.update(self._staged)
        self._staged = None
        self._saved = None
        self.committed_identity = self.identity
        self.committed_seq = self.seq

    def rollback(self) -> None:
        if self.stats is not None:
            self.stats.rollback()
        if self._saved is not None:
            (self.policy, self.seq, self.policy_recorded, self.policy_seq, self.identity,
             self.identity_seq, ignored) = self._saved
            del self.ignored_identities[ignored:]
        self._staged = None
        self._saved = None

    def _put(self, fault: Fault) -> None:
        if self._staged is not None:
            self._staged[fault.fault_code] = fault
        else:
            self._faults[fault.fault_code] = fault

    # -- applying ----------------------------------------------------------------------------
    def apply_all(self, records: Iterable[LogRecord]) -> list[Transition]:
        """Apply records in order (replay); returns the transitions they caused."""
        found: list[Transition] = []
        for record in records:
            transition = self.apply(record).transition
            if transition is not None:
                found.append(transition)
        return found

    def apply(self, record: LogRecord) -> Effect:
        if record.seq != self.seq + 1:
            raise ValueError(f"record seq {record.seq} does not follow {self.seq}")
        self.seq = record.seq
        if self._saved is None:
            self.committed_seq = record.seq
        event = record.event
        if isinstance(event, FaultAcknowledged | FaultShelved | FaultUnshelved):
            return self._operated(record, event)
        effect = self._apply(record, event)
        if self.stats is not None:
            if isinstance(event, GoalOutcome):
                self.stats.observe_goal(record, event)
            elif not isinstance(event, PolicyChanged | LedgerIdentified):
                fault = effect.fault or self.get(event.fault_code)
                self.stats.observe(record, effect.transition, fault)
        return effect

    def _operated(self, record: LogRecord,
                  event: FaultAcknowledged | FaultShelved | FaultUnshelved) -> Effect:
        before = self.get(event.fault_code)
        effect = self._operator(record, event, before)
        if self.stats is not None and effect.fault is not None and before is not None:
            self.stats.observe_operator(record, event, before, effect.fault)
        return effect

    def apply_selected(self, record: LogRecord) -> Effect:
        """Apply a record of a selection of the log: some faults' records plus every policy
        change. Faults never affect one another, so those faults end as in a full replay."""
        if record.seq <= self.seq:
            raise ValueError(f"record seq {record.seq} does not follow {self.seq}")
        self.seq = record.seq - 1
        return self.apply(record)

    def _apply(self, record: LogRecord, event: DomainEvent) -> Effect:
        if isinstance(event, FaultReported):
            return self._reported(record, event)
        if isinstance(event, FaultCleared):
            return self._cleared(record, event)
        if isinstance(event, FaultConfirmedByTimer):
            return self._move(record, event.fault_code, FaultStatus.PREFAILED, "timer", "timer")
        if isinstance(event, ReclassifiedOnStartup):
            return self._move(record, event.fault_code, FaultStatus.HEALED, "startup", "startup")
        if isinstance(event, PolicyChanged):
            self.policy = Policy.model_validate(event.policy)
            self.policy_recorded = True
            self.policy_seq = record.seq
        elif isinstance(event, LedgerIdentified):
            self._identified(record, event)
        return _NOTHING

    def _identified(self, record: LogRecord, event: LedgerIdentified) -> None:
        """The first identity is the log's; it changes no fault and announces nothing."""
        if self.identity is not None:
            if record.seq != self.identity_seq:  # (a replay over a saved identity meets it)
                self.ignored_identities.append(record.seq)
            return
        self.identity = LedgerIdentity(event.robot_id, event.ledger_id)
        self.identity_seq = record.seq
        if self._saved is None:
            self.committed_identity = self.identity

    def _reported(self, record: LogRecord, event: FaultReported) -> Effect:
        old = self.get(event.fault_code)
        params = self.policy.resolve(event.source_id, event.fault_code)
        new = debounce.apply_report(old, event, params, record.occurred_at_ns)
        if new is None or new is old:
            return _NOTHING
        if new.status is FaultStatus.CONFIRMED and not new.confirmed_ns:
            new = new._replace(confirmed_ns=record.occurred_at_ns)
        self._put(new)
        old_status = None if old is None else old.status
        effect: Effect = tuple_new(Effect, (  # once per report: see tuple_new
            new,
            self._transition(record, new, old_status, EVENT_TYPE_NAMES[event.event_type],
                             event.source_id),
            for_status_change(old_status, new.status),
        ))
        return effect

    def _cleared(self, record: LogRecord, event: FaultCleared) -> Effect:
        old = self.get(event.fault_code)
        if old is None:
            return _NOTHING
        new = old._replace(status=FaultStatus.CLEARED, last_report_failed=False)
        self._put(new)
        transition = self._transition(record, new, old.status, "clear", event.actor)
        return Effect(new, transition, NotificationType.CLEARED)

    def _move(
        self, record: LogRecord, code: str, required: FaultStatus, cause: str, source: str
    ) -> Effect:
        """Timer confirmation (PREFAILED→CONFIRMED) or startup reclassification (HEALED→CLEARED)."""
        old = self.get(code)
        if old is None or old.status is not required:
            return _NOTHING
        if required is FaultStatus.PREFAILED:
            new = old._replace(status=FaultStatus.CONFIRMED,
                               confirmed_ns=old.confirmed_ns or record.occurred_at_ns)
            notification = NotificationType.CONFIRMED
        else:
            new = old._replace(status=FaultStatus.CLEARED, last_report_failed=False)
            notification = None
        self._put(new)
        return Effect(new, self._transition(record, new, old.status, cause, source), notification)

    def _operator(self, record: LogRecord,
                  event: FaultAcknowledged | FaultShelved | FaultUnshelved,
                  old: Fault | None) -> Effect:
        """What people did: the status and counts stay; a record that no longer fits the
        fault (an acknowledgement of an episode that is over, or already acknowledged;
        the end of a shelving that is not in force) changes nothing."""
        if old is None:
            return _NOTHING
        at = record.occurred_at_ns
        if isinstance(event, FaultAcknowledged):
            if (old.status is FaultStatus.CLEARED or old.acknowledged is not None
                    or old.episode != event.episode):
                return _NOTHING
            new = old._replace(acknowledged=Acknowledgement(event.actor, event.note, at,
                                                            record.seq))
            notification = NotificationType.ACKNOWLEDGED
        elif isinstance(event, FaultShelved):
            new = old._replace(shelved=Shelving(event.actor, event.reason, at, event.until_ns,
                                                record.seq))
            notification = NotificationType.SHELVED
        else:
            if old.shelved is None:
                return _NOTHING
            new = old._replace(shelved=None)
            notification = NotificationType.UNSHELVED
        self._put(new)
        return Effect(new, None, notification)

    @staticmethod
    def _transition(
        record: LogRecord, new: Fault, old: FaultStatus | None, cause: str, source: str
    ) -> Transition | None:
        if old is new.status:
            return None
        return Transition(record.seq, new.fault_code, old, new.status, record.occurred_at_ns,
                          cause, source)
