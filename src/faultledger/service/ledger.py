"""FaultLedger: the one API that the CLI, the ROS node and the HTTP server call (SPEC §6)."""

from __future__ import annotations

import contextlib
import logging
import re
import socket
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from types import TracebackType

from sqlalchemy import Connection

from faultledger.domain import attention, queries, validation
from faultledger.domain.clock import NS_PER_SECOND, from_ns, to_ns
from faultledger.domain.events import FaultCleared, LogRecord
from faultledger.domain.fault import Fault
from faultledger.domain.identity import LedgerIdentity
from faultledger.domain.notifications import Notification
from faultledger.domain.periods import default_calendar
from faultledger.domain.policy import Policy
from faultledger.domain.projector import Projector, Transition
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import DEFAULT_ESTOP_CODES, StatsRow
from faultledger.errors import (
    DamagedDatabaseError,
    FaultLedgerError,
    InvalidInputError,
    Reason,
    clipped,
)
from faultledger.service import audit, operator, statistics
from faultledger.service.arguments import aware_ns, check_limit, record_filter, seq_number
from faultledger.service.commands import goal_command, report_command
from faultledger.service.requests import GoalOutcomeRequest, ReportRequest
from faultledger.service.restore import (
    DAMAGED,
    UnreadableRecord,
    apply_all,
    restore,
    save_replay,
)
from faultledger.service.results import (
    ClearResult,
    Downtime,
    EntityLookup,
    FaultLookup,
    OperatorResult,
    ReportResult,
    VerifyReport,
)
from faultledger.service.telemetry import Snapshot
from faultledger.service.writer import (
    CatchUp,
    Clear,
    Command,
    ConfirmOverdue,
    Exclusive,
    ExpireShelvings,
    Operate,
    ReclassifyHealed,
    RecordPolicy,
    Writer,
    identity_mismatch,
)
from faultledger.store import event_log, migrate, projections, stat_tables
from faultledger.store.database import Database, describe

log = logging.getLogger(__name__)

Callback = Callable[[Notification], None]
_SELECTIVE_REPLAY_CODES = 500
"""A catch-up touching more fault codes than this replays the whole log instead."""


@dataclass(frozen=True, slots=True)
class Restored:
    """What ``open`` found: the numbers a fault manager prints at startup."""

    events: int
    faults: int
    replayed: int


class Subscription:
    def __init__(self, ledger: FaultLedger, callback: Callback) -> None:
        self._ledger = ledger
        self.callback = callback

    def cancel(self) -> None:
        self._ledger._unsubscribe(self)


class FaultLedger:
    """Event-sourced fault manager over one database. Thread-safe; use ``open`` to create."""

    def __init__(self, db: Database, projector: Projector, policy: Policy | None,
                 max_batch: int, restored: Restored, robot_id: str | None = None,
                 serving: bool = False) -> None:
        self._db = db
        self._subscriptions: list[Subscription] = []
        self._subscriptions_lock = threading.Lock()
        self._writer = Writer(db, projector, policy, self._announce, max_batch,
                              robot_id=robot_id or default_robot_id(),
                              expected_robot_id=robot_id, serving=serving)
        self.restored = restored
        self.calendar: ShiftCalendar = default_calendar()
        """The shift calendar ``stats`` uses unless a call names another."""
        self.estop_codes: tuple[str, ...] = DEFAULT_ESTOP_CODES
        """Globs of the codes whose activations are e-stops (the ``estops`` figure)."""
        self._stop = threading.Event()
        self._ticker: threading.Thread | None = None

    # -- lifecycle -------------------------------------------------------------------------------
    @classmethod
    def open(cls, url: str, policy: Policy | None = None, *, max_batch: int = 512,
             upgrade: bool = True, create: bool = True, background: bool | None = None,
             calendar: ShiftCalendar | None = None,
             estop_codes: Sequence[str] | None = None,
             robot_id: str | None = None, database: Database | None = None) -> FaultLedger:
        """Open (create, migrate) the database and restore state: projections + log tail.

        With a ``policy`` this process is a serving writer: the policy is recorded when it
        differs from the log's, HEALED faults it cannot heal become CLEARED, a background
        thread runs time-based confirmation, and a new SQLite WAL is given its working size
        at the first write (``background`` decides both when given). Without one, the log's
        own policy applies and opening writes nothing (unless ``upgrade`` has a migration).

        ``robot_id`` is recorded in the log's identity by its first write (default: the host
        name). Given, a log that records another robot_id is refused
        (IdentityMismatchError); not given, a log's recorded identity is used as it is (a
        copy read elsewhere opens).
        """
        if robot_id is not None:
            problem = validation.robot_id_error(robot_id)
            if problem is not None:
                raise InvalidInputError(problem)
        db = database if database is not None else Database(url, create=create)
        try:
            migrate.ensure_current(db, upgrade=upgrade)
            projector, events, replayed = restore(db)
            recorded = projector.identity
            if robot_id is not None and recorded is not None and recorded.robot_id != robot_id:
                raise identity_mismatch(url, recorded, robot_id)
        except FaultLedgerError:
            db.dispose()
            raise
        except Exception as error:  # stored content this code cannot read: damage, not a bug
            db.dispose()
            detail = str(error) if isinstance(error, UnreadableRecord) else clipped(error)
            raise DamagedDatabaseError(
                f"database {describe(url)} cannot be restored ({detail}): its content "
                "is damaged or was edited; restore a backup") from error
        except BaseException:
            db.dispose()
            raise
        restored = Restored(events, len(projector.committed()), replayed)
        serving = background if background is not None else policy is not None
        ledger = cls(db, projector, policy, max_batch, restored, robot_id, serving)
        if calendar is not None:
            ledger.calendar = calendar
        if estop_codes is not None:
            ledger.estop_codes = statistics.estop_globs(estop_codes)
        try:
            if policy is not None:
                ledger._writer.submit(RecordPolicy())
                ledger._writer.submit(ReclassifyHealed(policy))
            if serving:
                ledger._start_ticker()
        except BaseException:
            ledger.close()
            raise
        return ledger

    def close(self) -> None:
        self._stop.set()
        if self._ticker is not None:
            self._ticker.join()
        self._writer.close()
        self._db.dispose()

    def __enter__(self) -> FaultLedger:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    @property
    def url(self) -> str:
        return self._db.url

    @property
    def policy(self) -> Policy:
        """The policy in force: the last one recorded in the log (or the default)."""
        return self._writer.projector.policy

    @property
    def telemetry(self) -> Snapshot:
        """What this process's writer appended, and its commit latencies (for metrics)."""
        return self._writer.telemetry.snapshot()

    @property
    def identity(self) -> LedgerIdentity | None:
        """The log's robot_id and ledger_id, as its first ``ledger_identified`` record says;
        None before any writer recorded one.

        Until this process sees one, the database is asked: another process (a serving
        writer beside a reading one) may have recorded it since this one opened.
        """
        found = self._writer.projector.committed_identity
        if found is None:
            with contextlib.suppress(FaultLedgerError):
                self.catch_up()  # its record, whether or not that process saved projections
                found = self._writer.projector.committed_identity
        if found is None:
            try:
                with self._db.reading() as conn:
                    stored = projections.load_identity(conn)
            except FaultLedgerError:
                return None
            found = None if stored is None else stored[0]
        return found

    @property
    def last_seq(self) -> int:
        """The newest record whose effects readers see (not one still being committed)."""
        return self._writer.projector.committed_seq

    # -- writes ----------------------------------------------------------------------------------
    def report(self, fault_code: str, event_type: str | int, severity: int = 0,
               description: str = "", source_id: str = "", at: datetime | None = None,
               event_id: str | None = None) -> ReportResult:
        """Record one FAILED/PASSED report; returns once it is durable (or rejected)."""
        command = report_command(ReportRequest(fault_code, event_type, severity, description,
                                               source_id, at, event_id))
        if isinstance(command, ReportResult):
            return command
        try:
            result: ReportResult = self._writer.submit(command)
        except FaultLedgerError as error:
            return ReportResult(False, str(error), reason=error.reason)
        return result

    def report_many(self, requests: Sequence[ReportRequest]) -> list[ReportResult]:
        """Record several reports in order, sharing commits; one result per request.

        For a caller that receives reports in bursts (a ROS service draining its queue, a
        bridge translating one message into many reports): one wait instead of one per report.
        """
        return self._submit_checked([report_command(request) for request in requests])

    def record_goal_outcome(self, action: str, goal_id: str, status: str, server_node: str = "",
                            at: datetime | None = None) -> ReportResult:
        """Record the terminal status (SUCCEEDED, ABORTED, CANCELED) of one action goal.

        Once per (action, goal_id): a repeat is answered accepted and ``duplicate`` and
        stores nothing. The record changes no fault and announces nothing; the statistics
        count it (``aborted_goals`` ...). Returns once it is durable (or rejected).
        """
        return self.record_goal_outcomes(
            [GoalOutcomeRequest(action, goal_id, status, server_node, at)])[0]

    def record_goal_outcomes(self, requests: Sequence[GoalOutcomeRequest]
                             ) -> list[ReportResult]:
        """Record several goal outcomes in order, sharing commits; one result per request."""
        return self._submit_checked([goal_command(request) for request in requests])

    def _submit_checked(self, checked: list[Command | ReportResult]) -> list[ReportResult]:
        """Submit the valid commands together; a rejection stays in its request's place."""
        commands = [c for c in checked if not isinstance(c, ReportResult)]
        try:
            answers = iter(self._writer.submit_all(commands))
        except FaultLedgerError as error:
            answers = iter([ReportResult(False, str(error), reason=error.reason)]
                           * len(commands))
        return [c if isinstance(c, ReportResult) else next(answers) for c in checked]

    def clear(self, fault_code: str, actor: str = "api", reason: str = "",
              at: datetime | None = None) -> ClearResult:
        problem = validation.clear_error(fault_code, actor, reason)
        if problem is None and at is not None:
            problem = validation.time_error("at", at)
        if problem is not None:
            return ClearResult(False, problem)
        occurred_ns = time.time_ns() if at is None else to_ns(at)
        try:
            result: ClearResult = self._writer.submit(
                Clear(FaultCleared(fault_code, actor, reason), occurred_ns))
        except FaultLedgerError as error:
            return ClearResult(False, str(error), reason=error.reason)
        return result

    # -- the operator's day (docs/semantics.md) ---------------------------------------------
    def acknowledge(self, fault_code: str, actor: str = "api", note: str = "",
                    at: datetime | None = None) -> OperatorResult:
        """Record that ``actor`` has seen the fault's current episode; the status stays. A
        second acknowledgement of one episode records nothing (reason ``duplicate``)."""
        return self._operate(operator.acknowledge(fault_code, actor, note, at))

    def shelve(self, fault_code: str, duration: str | timedelta | float, actor: str = "api",
               reason: str = "", at: datetime | None = None) -> OperatorResult:
        """Hide a known nuisance from lists and alerts for ``duration`` (``2h``, a timedelta,
        seconds; at most 30 days); its status and counts go on. Shelving a shelved fault
        replaces the shelving (a new end)."""
        return self._operate(operator.shelve(fault_code, actor, reason, duration, at))

    def unshelve(self, fault_code: str, actor: str = "api", reason: str = "",
                 at: datetime | None = None) -> OperatorResult:
        return self._operate(operator.unshelve(fault_code, actor, reason, at))

    def _operate(self, command: Operate | OperatorResult) -> OperatorResult:
        if isinstance(command, OperatorResult):
            return command
        try:
            result: OperatorResult = self._writer.submit(command)
        except FaultLedgerError as error:
            return OperatorResult(False, str(error), reason=error.reason)
        return result

    def run_timers(self, now: datetime | None = None) -> int:
        """Confirm PREFAILED faults whose last FAILED is ``auto_confirm_after_sec`` old, and
        end the shelvings expired by ``now`` (each record stamped with its expiry)."""
        now_ns = time.time_ns() if now is None else to_ns(now)
        count: int = self._writer.submit(ConfirmOverdue(now_ns))
        count += self._expire_shelvings(now_ns)
        return count

    def _expire_shelvings(self, now_ns: int) -> int:
        """Only a commit when one is due: the ticker asks every second."""
        if not attention.expired_shelvings(self._writer.projector.committed(), now_ns):
            return 0
        ended: int = self._writer.submit(ExpireShelvings(now_ns))
        return ended

    def rebuild(self) -> int:
        """Drop the projections and replay the whole log; returns the records replayed."""

        def action(conn: Connection, writer: Writer) -> int:
            projector = save_replay(conn)
            writer.projector = projector
            return projector.seq

        count: int = self._writer.submit(Exclusive(action))
        return count

    # -- reads -----------------------------------------------------------------------------------
    def _saved(self) -> None:
        """Before a read of the saved projections or statistics: every record appended so
        far (by any process) is in them. Writers save projections behind their commits
        (docs/architecture.md, "Saving the projections")."""
        self.catch_up()
        self._writer.save_projections()

    def _faults(self) -> list[Fault]:
        return self._writer.projector.committed()

    def catch_up(self) -> int:
        """Apply the records other processes appended since and return the log's last seq:
        for readers that must see them now rather than at the next background tick."""
        with self._db.reading() as conn:
            stored = event_log.head(conn)[0]
        if stored == self.last_seq:
            return stored
        result: int = self._writer.submit(CatchUp())
        return result

    def list_faults(self, statuses: Iterable[str] = (), severity: int | None = None
                    ) -> list[Fault]:
        return queries.select(self._faults(), statuses, severity)

    def triage(self, statuses: Iterable[str] = (), severity: int | None = None,
               shelved: str = "hide", now: datetime | None = None) -> list[Fault]:
        """The operator's list (``faultledger list``, the dashboard): ``list_faults``
        without the shelved faults (``shelved="only"``: only them; ``"show"``: all),
        unacknowledged faults first. ``list_faults`` stays medkit's list."""
        now_ns = time.time_ns() if now is None else aware_ns(now, "now")
        try:
            return attention.triage(self.list_faults(statuses, severity), now_ns, shelved)
        except ValueError as error:
            raise InvalidInputError(str(error)) from None

    def all_faults(self) -> list[Fault]:
        return sorted(self._faults(), key=lambda f: f.fault_code)

    def lookup_fault(self, fault_code: str) -> FaultLookup:
        problem = validation.fault_code_error(fault_code)
        if problem is not None:
            return FaultLookup(False, problem)
        fault = self._writer.projector.get_committed(fault_code)
        if fault is None:
            return FaultLookup(False, f"Fault not found: {fault_code}", reason=Reason.NOT_FOUND)
        return FaultLookup(True, "", fault)

    def get_fault(self, fault_code: str) -> Fault | None:
        problem = validation.fault_code_error(fault_code)
        if problem is not None:
            raise InvalidInputError(problem)
        return self._writer.projector.get_committed(fault_code)

    def list_faults_for_entity(self, entity_id: str) -> list[Fault]:
        return queries.for_entity(self._faults(), entity_id)

    def lookup_entity(self, entity_id: str) -> EntityLookup:
        """list_faults_for_entity with validation, as an answer for adapters."""
        problem = validation.entity_error(entity_id)
        if problem is not None:
            return EntityLookup(False, problem)
        return EntityLookup(True, "", self.list_faults_for_entity(entity_id))

    def history(self, code: str | None = None, since: datetime | int | None = None,
                until: datetime | int | None = None, source: str | None = None,
                kinds: Iterable[str] = (), limit: int | None = None, *,
                codes: Sequence[str] | None = None, from_seq: int | None = None,
                to_seq: int | None = None) -> list[LogRecord]:
        """Log records in seq order; ``since``/``until`` bound ``occurred_at`` as [since, until).

        A bound may be an int of nanoseconds since the epoch: a datetime holds only
        microseconds, and ROS stamps carry nanoseconds. ``code`` is one exact code; ``codes``
        are exact codes or case-sensitive fnmatch globs (``HW_*_EMERGENCY_STOP``), any of which
        matches; ``from_seq``/``to_seq`` are inclusive. An unknown kind or a bad seq range
        raises InvalidInputError rather than answering nothing. For exports of any size,
        ``export_history`` streams the same selection as stored rows.
        """
        where = record_filter(code, since, until, source, kinds, limit, codes, from_seq, to_seq)
        with self._db.reading() as conn:
            return event_log.find(conn, where)

    def stats(self, by: str = "shift", since: datetime | str | None = None,
              until: datetime | str | None = None, codes: Sequence[str] | None = None,
              group_by: Sequence[str] = (), *, calendar: ShiftCalendar | None = None,
              as_of: datetime | None = None,
              budget: statistics.StatsBudget | None = None) -> list[StatsRow]:
        """Figures per period (and group) of docs/statistics.md over [since, until).

        Bounds may be datetimes, ISO dates or date-times (local to the calendar's zone) or
        shift ids; ``as_of`` (default now) ends the CONFIRMED episodes still open. A
        ``budget`` refuses (InvalidInputError) a query that would do more work than it allows.
        """
        query = statistics.StatsQuery(by, since, until, codes, group_by,
                                      calendar or self.calendar, as_of, self.estop_codes,
                                      budget)
        self._saved()
        return statistics.compute(self._db, query)

    def downtimes(self, since: datetime, until: datetime, limit: int | None = None, *,
                  as_of: datetime | None = None) -> list[Downtime]:
        """The CONFIRMED episodes overlapping [since, until), most time inside the range
        first (then the longest, then the earliest).

        An episode still open ends at ``as_of`` (default now), as in ``stats``; episodes
        with no time inside the range (0 s, or starting after ``as_of``) are left out.
        """
        since_ns, until_ns = aware_ns(since, "since"), aware_ns(until, "until")
        as_of_ns = time.time_ns() if as_of is None else aware_ns(as_of, "as_of")
        check_limit(limit)
        if since_ns >= until_ns:
            raise InvalidInputError("since must be before until")
        self._saved()
        with self._db.reading() as conn:
            episodes = stat_tables.episodes(conn, since_ns, until_ns, None)
        found: list[Downtime] = []
        for e in episodes:
            end_ns = e.stop_ns(as_of_ns)  # never before the start (a clock run backwards)
            inside = min(end_ns, until_ns) - max(e.start_ns, since_ns)
            if inside > 0:
                found.append(Downtime(
                    e.code, e.source, e.severity, from_ns(e.start_ns),
                    None if e.end_ns is None else from_ns(e.end_ns),
                    (end_ns - e.start_ns) / NS_PER_SECOND, inside / NS_PER_SECOND))
        found.sort(key=lambda d: (-d.seconds_in_range, -d.seconds, d.start, d.fault_code))
        return found if limit is None else found[:limit]

    def transitions(self, code: str | None = None) -> list[Transition]:
        self._saved()
        with self._db.reading() as conn:
            return projections.load_transitions(conn, code)

    def state_at(self, when: datetime | int) -> list[Fault]:
        """Faults (any status) after the log prefix up to seq ``when``, or recorded by a time."""
        upto = seq_number(when, "when") if isinstance(when, int) else aware_ns(when, "when")
        with self._db.reading() as conn:
            if not isinstance(when, int):
                upto = event_log.last_seq_recorded_by(conn, upto)
            projector = Projector()
            try:
                apply_all(projector, event_log.read_to_end(conn, upto_seq=upto))
            except UnreadableRecord as error:
                raise DamagedDatabaseError(f"{error}: {DAMAGED}; restore a backup") from error
        return sorted(projector.committed(), key=lambda f: f.fault_code)

    def verify(self, from_seq: int | None = None, to_seq: int | None = None) -> VerifyReport:
        """Hash chain intact, head anchored, persisted projections equal to a full replay.

        With ``from_seq``/``to_seq`` (inclusive) only that segment of the chain is checked,
        starting from the stored hash of record ``from_seq - 1``: whoever trusts that one hash
        (anchored elsewhere, or covered by an earlier check) needs nothing before it. The
        checkpoint is compared when the segment holds its seq; projections are not replayed.
        The whole-log check also runs the database's own integrity check (SQLite); a segment
        does not (it reads only its records).
        """
        if from_seq is None and to_seq is None:
            # So the check covers this process's latest commits too (a log that cannot be
            # written is checked as saved).
            with contextlib.suppress(FaultLedgerError):
                self._saved()
        return audit.verify(self._db, from_seq, to_seq)

    # -- notifications ---------------------------------------------------------------------------
    def notifications_after(self, seq: int, limit: int = 1000) -> list[Notification]:
        """The announcements of the records after ``seq``, as subscribers received them (at
        most ``limit``, in seq order), derived from the log: how a stream client that was
        away (or a restarted server) catches up with nothing missed and nothing twice.

        Only the faults those records touch are replayed, unless there are very many.
        """
        seq = seq_number(seq, "seq")
        check_limit(limit)
        found: list[Notification] = []
        with self._db.reading() as conn:
            codes = event_log.codes_after(conn, seq, _SELECTIVE_REPLAY_CODES)
            projector = Projector()
            if codes is None:
                records = event_log.read(conn)
                apply = projector.apply
            else:
                records = event_log.read_of_codes(conn, codes)
                apply = projector.apply_selected
            for record in records:
                effect = apply(record)
                if (record.seq > seq and effect.notification is not None
                        and effect.fault is not None):
                    found.append(Notification(effect.notification, effect.fault,
                                              record.recorded_at_ns, record.seq))
                    if len(found) >= limit:
                        break
        return found

    def subscribe(self, callback: Callback) -> Subscription:
        """Call ``callback(notification)`` after each announced change is durable.

        Callbacks run on the committing thread, in log order, before the report is answered:
        keep them short (hand heavy work to a queue).
        """
        subscription = Subscription(self, callback)
        with self._subscriptions_lock:
            self._subscriptions.append(subscription)
        return subscription

    def _unsubscribe(self, subscription: Subscription) -> None:
        with self._subscriptions_lock:
            if subscription in self._subscriptions:
                self._subscriptions.remove(subscription)

    def _announce(self, notifications: list[Notification]) -> None:
        with self._subscriptions_lock:
            subscriptions = list(self._subscriptions)
        for notification in notifications:
            for subscription in subscriptions:
                try:
                    subscription.callback(notification)
                except Exception:
                    log.exception("subscriber %r failed", subscription.callback)

    # -- background ------------------------------------------------------------------------------
    def _start_ticker(self) -> None:
        self._ticker = threading.Thread(target=self._tick, name="faultledger-timers",
                                        daemon=True)
        self._ticker.start()

    def _tick(self) -> None:
        """Time-based confirmation and pick-up of records other processes appended."""
        while not self._stop.wait(self._tick_interval()):
            try:
                self.catch_up()
                self._writer.save_if_due()
                if self.policy.auto_confirm_after_sec > 0:
                    self._writer.submit(ConfirmOverdue(time.time_ns()))
                self._expire_shelvings(time.time_ns())
            except FaultLedgerError as error:
                log.warning("background check failed: %s", error)

    def _tick_interval(self) -> float:
        after = self.policy.auto_confirm_after_sec
        return 1.0 if after <= 0 else min(1.0, max(0.05, after / 10))


def default_robot_id() -> str:
    """The host name as a robot_id (characters a robot_id cannot hold become ``-``): what a
    log records when no robot_id is configured."""
    name = re.sub(r"[^A-Za-z0-9_.\-]", "-", socket.gethostname())
    name = name[:validation.MAX_ROBOT_ID_LENGTH].lstrip("_.-")
    return name or "robot"
