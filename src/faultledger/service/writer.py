"""The single write path: queued commands become records committed in groups.

Every reporting thread enqueues a command and waits; one of them at a time (the leader)
takes everything queued (up to ``max_batch``), applies it to the projector, appends the
records and the changed projections in ONE transaction, and only then answers the waiting
callers and announces the changes. Many concurrent reports therefore share one fsync (group
commit), and nothing is acknowledged before it is durable.
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

from sqlalchemy import Connection

from faultledger.domain import attention, debounce
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
    OperatorEvent,
    PolicyChanged,
    ReclassifiedOnStartup,
)
from faultledger.domain.identity import LedgerIdentity
from faultledger.domain.notifications import Notification
from faultledger.domain.policy import Policy
from faultledger.domain.projector import Effect, Projector, Transition
from faultledger.errors import (
    DatabaseFullError,
    FaultLedgerError,
    IdentityMismatchError,
    InternalError,
    LedgerClosedError,
    Reason,
    StoreError,
    WriteConflictError,
    clipped,
)
from faultledger.service import restore
from faultledger.service.event_ids import new_event_id
from faultledger.service.results import ClearResult, OperatorResult, ReportResult
from faultledger.service.telemetry import Telemetry
from faultledger.store import event_log, log_index, projections, stat_tables
from faultledger.store.database import Database, WriteConnection, describe

log = logging.getLogger(__name__)

GATHER_WAIT_S = 0.0003

recorded_clock = time.time_ns
"""The wall clock that stamps ``recorded_at`` (a test replaces it to write a log of the
past; a module variable, so that also works when this module is compiled)."""


@dataclass(frozen=True, slots=True)
class Report:
    event: FaultReported
    occurred_ns: int
    event_id: str
    explicit_id: bool


@dataclass(frozen=True, slots=True)
class Clear:
    event: FaultCleared
    occurred_ns: int


@dataclass(frozen=True, slots=True)
class Operate:
    """An acknowledgement, shelving or unshelving by a person; decided against the fault as
    it is inside the commit (an acknowledgement gets the episode then)."""

    event: OperatorEvent
    occurred_ns: int


@dataclass(frozen=True, slots=True)
class ExpireShelvings:
    """End the shelvings expired by ``now_ns``, each stamped with its expiry time."""

    now_ns: int


@dataclass(frozen=True, slots=True)
class RecordGoal:
    """A goal outcome; its event_id is derived from (action, goal id), so a repeat of the
    same goal is recognised and stored once."""

    event: GoalOutcome
    occurred_ns: int
    event_id: str


@dataclass(frozen=True, slots=True)
class ConfirmOverdue:
    now_ns: int


@dataclass(frozen=True, slots=True)
class ReclassifyHealed:
    policy: Policy


@dataclass(frozen=True, slots=True)
class RecordPolicy:
    pass


@dataclass(frozen=True, slots=True)
class CatchUp:
    """Apply records another process appended (no announcements: that process made them)."""


@dataclass(frozen=True, slots=True)
class Exclusive:
    """Run ``action(conn, writer)`` alone inside a write transaction (e.g. rebuild)."""

    action: Callable[[Connection, Writer], Any]


@dataclass(frozen=True, slots=True)
class SaveProjections:
    """Save the projections now (before a read of the saved ones)."""


Command = (Report | Clear | Operate | RecordGoal | ConfirmOverdue | ExpireShelvings
           | ReclassifyHealed | RecordPolicy | CatchUp | Exclusive | SaveProjections)

SAVE_EVERY_RECORDS = 1_000
"""Unsaved records at which a commit also saves the projections (docs/architecture.md,
"Saving the projections")."""
SAVE_AFTER_S = 0.5
"""Age of the oldest unsaved commit at which ``save_if_due`` saves the projections."""


def _held_lock() -> threading.Lock:
    lock = threading.Lock()
    lock.acquire()
    return lock


@dataclass(slots=True)
class _Caller:
    """One thread waiting in ``submit``/``submit_all`` for its commands."""

    unanswered: int
    wake: threading.Lock = field(default_factory=_held_lock)
    """Released once: when all its commands are answered, or when it is made leader."""
    then: _Caller | None = None
    """Answered by the same commit: woken by this caller as soon as its own wait returns."""


@dataclass(slots=True)
class _Pending:
    command: Command
    caller: _Caller
    done: bool = False
    result: Any = None
    error: BaseException | None = None


class _Batch:
    """Records and effects of one group commit, built against the staged projector.

    The first record of a log without identity is preceded by its ``ledger_identified``
    record (``robot_id``, a fresh ledger_id), whatever the command: so every log a writer
    touched names its robot, and the identity is part of the same commit.
    """

    def __init__(self, projector: Projector, recorded_ns: int, robot_id: str) -> None:
        self.projector = projector
        self.recorded_ns = recorded_ns
        self.robot_id = robot_id
        self.identified = False
        """Whether this batch appends the log's identity record."""
        self.records: list[LogRecord] = []
        self.transitions: list[Transition] = []
        self.notifications: list[Notification] = []

    def identify(self) -> None:
        """Append the log's identity unless it has one."""
        if self.projector.identity is None:
            self._append(LedgerIdentified(self.robot_id, str(uuid.uuid4())), self.recorded_ns)
            self.identified = True

    def add(self, event: DomainEvent, occurred_ns: int, event_id: str | None = None) -> int:
        self.identify()
        return self._append(event, occurred_ns, event_id)

    def _append(self, event: DomainEvent, occurred_ns: int, event_id: str | None = None) -> int:
        record = LogRecord(  # by position: a NamedTuple's call by keyword costs twice as much
            self.projector.seq + 1, event_id or new_event_id(), event, occurred_ns,
            self.recorded_ns)
        self._apply(record)
        return record.seq

    def _apply(self, record: LogRecord) -> None:
        effect: Effect = self.projector.apply(record)
        self.records.append(record)
        if effect.transition is not None:
            self.transitions.append(effect.transition)
        if effect.notification is not None and effect.fault is not None:
            self.notifications.append(
                Notification(effect.notification, effect.fault, record.recorded_at_ns,
                             record.seq))


class Writer:
    """Owns the projector and the only write path to the log of this process.

    Group commit without a writer thread (leader/follower): a caller queues its command;
    if no commit is running it becomes the leader and commits everything queued, on its own
    thread, until its own command is done; callers arriving meanwhile queue up and are
    committed together by the next leader, whom the finishing leader wakes. A lone reporter
    pays no thread hand-off; many reporters share each fsync.

    The callers a commit answered are woken one after another, each by the one before as it
    wakes (``_Caller.then``), not all at once: woken together, all but one of them went
    straight back to sleep waiting for the interpreter lock, one more context switch per
    report (8 threads: 2.5 -> 1.5 voluntary switches and 70 -> 61 µs of CPU per report;
    docs/performance.md, "Fifth round").
    """

    def __init__(
        self,
        db: Database,
        projector: Projector,
        desired_policy: Policy | None,
        announce: Callable[[list[Notification]], None],
        max_batch: int = 512,
        *,
        robot_id: str,
        expected_robot_id: str | None = None,
        serving: bool = False,
    ) -> None:
        self.db = db
        self.robot_id = robot_id
        """Who this writer records as the robot of a log without identity."""
        self.expected_robot_id = expected_robot_id
        """Given explicitly: a log of another robot is refused (also one identified by
        another process after this one opened it)."""
        self.projector = projector
        self.desired_policy = desired_policy
        self.max_batch = max_batch
        self._announce = announce
        self._connection = WriteConnection(db, presize=serving)
        self._queue: deque[_Pending] = deque()
        self._mutex = threading.Lock()
        self._arrived = threading.Condition(self._mutex)
        self._idle = threading.Condition(self._mutex)
        self._leading = False
        self._gathering = False
        self._gather_target = 0
        """Queued commands at which the gathering leader is woken."""
        self._callers = 0
        self._leader: int | None = None
        self._closed = False
        self._policy_checked: Policy | None = None
        self._head: tuple[int, str] | None = None
        self._reclaim = False
        """Set by "disk full": checkpoint and truncate the WAL before the next commit."""
        self._saved_seq = projector.seq
        """How far the saved projections go, as far as this writer knows (restore saved
        everything it replayed)."""
        self._recent_ids: dict[str, int] = {}
        """event_id -> seq of every record after ``_ids_after`` (appended by this writer or
        caught up with): with ``events_by_id`` up to the checkpoint, all a check of repeated
        event_ids needs, without reading the records after the checkpoint."""
        self._ids_after = projector.seq
        """Restore saved what it replayed, so the records up to here are indexed."""
        self._unsaved_codes: set[str] = set()
        self._unsaved_transitions: list[Transition] = []
        self._unsaved_since: float | None = None
        self.commits = 0
        self.telemetry = Telemetry()
        """Records appended and commit latency of this writer (``GET /metrics``)."""

    def submit(self, command: Command) -> Any:
        """Queue a command and return its result once it is durable (or failed)."""
        return self.submit_all([command])[0]

    def submit_all(self, commands: list[Command]) -> list[Any]:
        """Queue commands together (they share commits); their results once all are durable."""
        if not commands:
            return []
        if self._leader == threading.get_ident():
            raise FaultLedgerError(
                "a subscriber callback cannot report or clear synchronously (the commit that "
                "called it is still running); hand the call to another thread")
        caller = _Caller(len(commands))
        pendings = [_Pending(command, caller) for command in commands]
        last = pendings[-1]
        with self._mutex:
            if self._closed:
                raise LedgerClosedError("the ledger is closed")
            self._queue.extend(pendings)
            self._callers += 1
            if self._gathering and len(self._queue) >= self._gather_target:
                self._arrived.notify()  # once per group: each wake-up costs the leader a switch
            follow = self._leading
            self._leading = True
        if follow:
            caller.wake.acquire()  # all answered, or handed the leadership
            if caller.then is not None:  # the next caller answered by the same commit
                caller.then.wake.release()
        if not last.done:
            self._lead(last)
        with self._mutex:
            self._callers -= 1
        for pending in pendings:
            if pending.error is not None:
                raise pending.error
        return [pending.result for pending in pendings]

    def _lead(self, own: _Pending) -> None:
        """Commit queued groups until ``own`` (its caller's last command) is done, then hand
        over to the caller next in line."""
        self._leader = threading.get_ident()
        try:
            while not own.done:
                with self._mutex:
                    self._gather()
                    count = min(len(self._queue), self.max_batch)
                    batch = [self._queue.popleft() for _ in range(count)]
                for group in _split_exclusive(batch):
                    self._commit(group)
                answered: list[_Caller] = []
                for pending in batch:
                    caller = pending.caller
                    caller.unanswered -= 1
                    if caller.unanswered == 0 and caller is not own.caller:
                        answered.append(caller)
                if answered:
                    for first, second in pairwise(answered):
                        first.then = second
                    answered[0].wake.release()
        finally:
            self._leader = None
            with self._mutex:
                if self._queue:
                    # Its caller still waits (a caller's commands are contiguous in the queue).
                    self._queue[0].caller.wake.release()
                else:
                    self._leading = False
                    if self._closed:  # only ``close`` waits for the last leader
                        self._idle.notify_all()

    def _gather(self) -> None:
        """Wait up to GATHER_WAIT_S until every caller inside ``submit`` has queued.

        The callers answered by the previous commit are still inside ``submit`` or come
        straight back with their next report; waiting a fraction of an fsync for them lets
        them share the next one. A lone reporter never waits. Called with ``_mutex`` held.
        """
        target = min(self._callers, self.max_batch)
        if len(self._queue) >= target:
            return
        deadline = time.monotonic() + GATHER_WAIT_S
        self._gathering = True
        self._gather_target = target
        try:
            while len(self._queue) < target:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return
                self._arrived.wait(remaining)
        finally:
            self._gathering = False

    def save_projections(self) -> None:
        """Save the projections if they are behind this writer's commits (before a read of
        the saved projections or statistics in this process)."""
        if self._saved_seq != self.projector.committed_seq or self._unsaved_since is not None:
            self.submit(SaveProjections())

    def save_if_due(self) -> None:
        """Save the projections if the oldest unsaved commit is SAVE_AFTER_S old (the
        background tick): they follow the log within about a second."""
        since = self._unsaved_since
        if since is not None and time.monotonic() - since >= SAVE_AFTER_S:
            self.submit(SaveProjections())

    def close(self) -> None:
        """Refuse new commands, let the queued ones commit, save the projections, release
        the connection."""
        try:
            if not self._closed:
                self.save_projections()
        except FaultLedgerError as error:  # the log is whole; the next open replays its tail
            log.warning("projections not saved at close: %s", error)
        with self._mutex:
            self._closed = True
            while self._leading:
                self._idle.wait()
        self._connection.close()

    def _commit(self, group: list[_Pending]) -> None:
        """Commit one group; after a concurrent append by another process, retry once.

        Commands are validated before they are queued, so a group should never fail because
        of one of them; should one still raise something unexpected, every command of the
        group is committed alone, so only the culprit fails (isolation as a last resort).
        """
        started = time.perf_counter()
        if self._reclaim:
            self._reclaim = not self._connection.reclaim()
        elif self._connection.low_space and self.commits % 100 == 0:
            self._connection.check_space()
        try:
            try:
                batch = self._write(group)
            except WriteConflictError:
                self._head = None
                batch = self._write(group)
        except FaultLedgerError as error:
            self._head = None
            if isinstance(error, DatabaseFullError):
                self._reclaim = not self._connection.reclaim()
            if len(group) > 1 and isinstance(error, WriteConflictError):
                # Still conflicting after catching up: a constraint one command breaks.
                self._commit_each(group, error)
                return
            self._fail(group, error)
            return
        except Exception as error:  # a bug must not leave callers waiting forever
            self._head = None
            if len(group) > 1:
                self._commit_each(group, error)
                return
            log.error("command %s failed: %s", type(group[0].command).__name__,
                      clipped(error))
            log.debug("command failed", exc_info=True)
            self._fail(group, InternalError(f"internal error while writing: {clipped(error)}"))
            return
        self.commits += 1
        if batch.records:
            self.telemetry.committed(batch.records, time.perf_counter() - started)
        if batch.notifications:
            self._announce(batch.notifications)
        for pending in group:
            pending.done = True

    def _commit_each(self, group: list[_Pending], error: BaseException) -> None:
        """Isolation: commit every command of a failed group alone, so only the culprit
        fails and the others are committed."""
        log.warning("commit of %d commands failed (%s); committing each alone", len(group),
                    clipped(error))
        for pending in group:
            self._commit([pending])

    def _write(self, group: list[_Pending]) -> _Batch:
        """Build, append and project one group in one transaction; the projector is staged
        and rolled back unless the commit succeeds.

        The head of the log (seq, hash) is remembered from the last commit and re-read only
        when another connection committed since (then its records are applied first, so
        decisions such as "Fault not found" see them). Should an append still collide,
        ``_commit`` retries after re-reading the head.
        """
        projector = self.projector
        projector.stage()
        batch = _Batch(projector, recorded_clock(), self.robot_id)
        saved = False
        try:
            kinds = {type(p.command) for p in group}
            exclusive = Exclusive in kinds
            with self._connection.transaction() as conn:
                if (self._head is None or self._head[0] != projector.seq
                        or self._connection.others_committed(conn) or CatchUp in kinds):
                    self._head = event_log.head(conn)
                    self._catch_up(conn, self._head[0], batch)
                self._check_identity()
                ids = [p.command.event_id for p in group
                       if (isinstance(p.command, Report) and p.command.explicit_id)
                       or isinstance(p.command, RecordGoal)]
                known = self._known_ids(conn, ids)
                for pending in group:
                    pending.result = self._build(pending.command, batch, known, conn)
                head_hash = self._head[1]
                if batch.records:
                    head_hash = event_log.append(conn, batch.records, head_hash)
                if not exclusive and (projector.seq - self._saved_seq >= SAVE_EVERY_RECORDS
                                      or SaveProjections in kinds):
                    self._save(conn, batch, head_hash)
                    saved = True
        except BaseException:
            projector.rollback()
            raise
        changed = [fault.fault_code for fault in projector.staged_faults()]
        projector.commit()
        self._head = (projector.seq, head_hash)
        if saved or exclusive:  # (an exclusive action saved a whole replay: rebuild)
            self._recent_ids.clear()  # all indexed now
            self._ids_after = projector.seq
            self._unsaved_codes.clear()
            self._unsaved_transitions.clear()
            self._unsaved_since = None
            if self.projector.stats is not None:
                self.projector.stats.take()
            self._saved_seq = self.projector.committed_seq
        elif projector.seq != self._saved_seq:
            recent = self._recent_ids
            for record in batch.records:
                recent[record.event_id] = record.seq
            self._unsaved_codes.update(changed)
            self._unsaved_transitions.extend(batch.transitions)
            if self._unsaved_since is None:
                self._unsaved_since = time.monotonic()
        return batch

    def _save(self, conn: Connection, batch: _Batch, head_hash: str) -> None:
        """Save what the commits since the last save changed (this group's included), in
        this group's transaction: the faults they touched, their transitions, statistics
        and identity, and the checkpoint at this group's last record.

        The changes are this writer's own record of what it applied since the saved
        checkpoint, so they are used only while the saved checkpoint is still where this
        writer left it. Where another process saved since (or a failed save at open left
        it behind), they overlap what is saved: then the projections are brought up to
        the head from what is saved instead (``restore.persist_lagging``).
        """
        projector = self.projector
        if projections.load_checkpoint(conn).seq != self._saved_seq:
            restore.persist_lagging(conn)
            return
        codes = self._unsaved_codes.union(f.fault_code for f in projector.staged_faults())
        changed = [fault for fault in map(projector.get, sorted(codes)) if fault is not None]
        projections.save(conn, changed, [*self._unsaved_transitions, *batch.transitions],
                         projections.Checkpoint(projector.seq, head_hash, projector.policy_seq))
        if projector.stats is not None:
            stat_tables.save(conn, projector.stats.peek(), projector.seq)
        if projector.identity is not None and projector.identity_seq > self._saved_seq:
            projections.save_identity(conn, projector.identity, projector.identity_seq)

    def _known_ids(self, conn: Connection, ids: list[str]) -> set[str]:
        """Which of these event_ids the log holds (under the write lock, after catching up):
        those indexed, and those of the records after the checkpoint, from memory when this
        writer saw all of them (the checkpoint is not behind what it last knew indexed),
        else read from the log."""
        if not ids:
            return set()
        indexed, saved = log_index.indexed_ids(conn, ids)
        if saved < self._ids_after:  # moved back, or a save at open failed
            return log_index.existing_ids(conn, ids)
        recent = self._recent_ids
        return indexed.union(event_id for event_id in ids if event_id in recent)

    def _check_identity(self) -> None:
        """Refuse to write into another robot's log (identified by another process since
        this one opened it: ``FaultLedger.open`` refuses the ones identified before)."""
        recorded = self.projector.identity
        if (self.expected_robot_id is not None and recorded is not None
                and recorded.robot_id != self.expected_robot_id):
            raise identity_mismatch(self.db.url, recorded, self.expected_robot_id)

    @staticmethod
    def _fail(group: list[_Pending], error: FaultLedgerError) -> None:
        for pending in group:
            if isinstance(pending.command, Report | RecordGoal):
                pending.result = ReportResult(False, str(error), reason=error.reason)
            elif isinstance(pending.command, Clear):
                pending.result = ClearResult(False, str(error), reason=error.reason)
            elif isinstance(pending.command, Operate):
                pending.result = OperatorResult(False, str(error), reason=error.reason)
            else:
                pending.error = error
            pending.done = True

    def _catch_up(self, conn: Connection, stored_seq: int, batch: _Batch) -> None:
        """Apply records another process appended (their effects join this writer's unsaved
        changes: that process may not have saved them yet).

        Their announcements go out with this group's, after its commit, so subscribers (the
        ROS events topic, HTTP streams) also see what other processes wrote, in seq order.
        """
        projector = self.projector
        if stored_seq == projector.seq:
            return
        if stored_seq < projector.seq:
            raise StoreError(
                f"the log ends at seq {stored_seq} but this process has applied {projector.seq}: "
                "the database was replaced or truncated underneath; restart faultledger"
            )
        for record in event_log.read(conn, after_seq=projector.seq):
            self._recent_ids[record.event_id] = record.seq  # committed by that process
            effect = projector.apply(record)
            if effect.transition is not None:
                batch.transitions.append(effect.transition)
            if effect.notification is not None and effect.fault is not None:
                batch.notifications.append(Notification(
                    effect.notification, effect.fault, record.recorded_at_ns, record.seq))

    def _ensure_policy(self, batch: _Batch) -> None:
        """Record the effective policy before the first record that depends on it."""
        projector = self.projector
        if projector.policy_recorded and projector.policy is self._policy_checked:
            return
        wanted = self.desired_policy or projector.policy
        if not projector.policy_recorded or projector.policy != wanted:
            batch.add(PolicyChanged(wanted.to_record()), batch.recorded_ns)
        self._policy_checked = projector.policy

    def _build(self, command: Command, batch: _Batch, known: set[str], conn: Connection) -> Any:
        projector = self.projector
        if isinstance(command, Report):
            return self._report(command, batch, known)
        if isinstance(command, RecordGoal):
            return self._goal(command, batch, known)
        if isinstance(command, Clear):
            code = command.event.fault_code
            if projector.get(code) is None:
                return ClearResult(False, f"Fault not found: {code}", reason=Reason.NOT_FOUND)
            self._ensure_policy(batch)
            seq = batch.add(command.event, command.occurred_ns)
            return ClearResult(True, f"Fault cleared: {code}", seq)
        if isinstance(command, Operate):
            return self._operate(command, batch)
        if isinstance(command, ExpireShelvings):
            due = attention.expired_shelvings(list(projector.snapshot().values()),
                                              command.now_ns)
            for fault in due:
                assert fault.shelved is not None
                batch.add(FaultUnshelved(fault.fault_code, attention.EXPIRY_ACTOR, "expired"),
                          fault.shelved.until_ns)
            return len(due)
        if isinstance(command, ConfirmOverdue):
            codes = projector.overdue_for_timer(command.now_ns)
            after = projector.policy.auto_confirm_after_sec
            for code in codes:
                batch.add(FaultConfirmedByTimer(code, after), command.now_ns)
            return len(codes)
        if isinstance(command, ReclassifyHealed):
            codes = projector.to_reclassify(command.policy)
            for code in codes:
                batch.add(ReclassifiedOnStartup(code, "healing is disabled in the policy"),
                          batch.recorded_ns)
            return codes
        if isinstance(command, RecordPolicy):
            batch.identify()  # a serving writer identifies the log when it starts
            self._ensure_policy(batch)
            return projector.policy
        if isinstance(command, CatchUp | SaveProjections):
            return projector.seq
        return command.action(conn, self)

    def _operate(self, command: Operate, batch: _Batch) -> OperatorResult:
        """The rules are the domain's (``attention``); the writer only applies them to the
        fault as this commit sees it."""
        event = command.event
        code = event.fault_code
        fault = self.projector.get(code)
        if isinstance(event, FaultAcknowledged):
            refusal = attention.acknowledge_refusal(fault, code)
        elif isinstance(event, FaultShelved):
            refusal = attention.shelve_refusal(fault, code)
        else:
            refusal = attention.unshelve_refusal(fault, code)
        if refusal is not None:
            return OperatorResult(False, refusal.message, reason=refusal.reason, fault=fault)
        assert fault is not None
        if isinstance(event, FaultAcknowledged):
            done = attention.already_acknowledged(fault)
            if done is not None:
                return OperatorResult(True, done, reason=Reason.DUPLICATE, fault=fault)
            event = event._replace(episode=fault.episode)
        seq = batch.add(event, command.occurred_ns)
        after = self.projector.get(code)
        return OperatorResult(True, attention.done_message(event), seq, fault=after)

    @staticmethod
    def _goal(command: RecordGoal, batch: _Batch, known: set[str]) -> ReportResult:
        """A goal outcome is appended as it is: it depends on no policy and changes no fault,
        so it records no policy and announces nothing."""
        if command.event_id in known:
            return ReportResult(True, "duplicate: this goal's outcome is already recorded",
                                event_id=command.event_id, duplicate=True)
        seq = batch.add(command.event, command.occurred_ns, command.event_id)
        known.add(command.event_id)
        return ReportResult(True, f"recorded as seq {seq}", seq, command.event_id)

    def _report(self, command: Report, batch: _Batch, known: set[str]) -> ReportResult:
        if command.explicit_id and command.event_id in known:
            return ReportResult(True, "duplicate: this event_id is already recorded",
                                event_id=command.event_id, duplicate=True)
        event = command.event
        fault = self.projector.get(event.fault_code)
        self._ensure_policy(batch)
        seq = batch.add(event, command.occurred_ns, command.event_id)
        known.add(command.event_id)
        if debounce.is_ignored(fault, event):  # logged all the same (SPEC §3): the full record
            why = "no such fault" if fault is None else "the fault is CLEARED"
            return ReportResult(True, f"recorded as seq {seq}; changes no fault ({why})", seq,
                                command.event_id)
        return ReportResult(True, f"recorded as seq {seq}", seq, command.event_id)


def identity_mismatch(url: str, recorded: LedgerIdentity, wanted: str) -> IdentityMismatchError:
    """The refusal of a log recording another robot_id, saying what to do instead."""
    return IdentityMismatchError(
        f"database {describe(url)} is the log of robot {recorded.robot_id!r} (ledger_id "
        f"{recorded.ledger_id}), not of robot {wanted!r}; nothing was written. If it is "
        f"another robot's log, give {wanted!r} its own database; if it is this robot's, set "
        f"robot_id to {recorded.robot_id!r} (a log keeps the robot_id it recorded first). "
        "Reading a copied log (verify, history) needs no robot_id: leave it unset")


def _split_exclusive(batch: list[_Pending]) -> list[list[_Pending]]:
    """Exclusive commands run in a transaction of their own, in queue order."""
    groups: list[list[_Pending]] = []
    current: list[_Pending] = []
    for pending in batch:
        if isinstance(pending.command, Exclusive):
            if current:
                groups.append(current)
                current = []
            groups.append([pending])
        else:
            current.append(pending)
    if current:
        groups.append(current)
    return groups
