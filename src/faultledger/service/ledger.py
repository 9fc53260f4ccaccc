"""FaultLedger: the one API that the CLI, the ROS node and the HTTP server call (SPEC §6)."""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from datetime import datetime
from types import TracebackType

from sqlalchemy import Connection

from faultledger.domain import queries, validation
from faultledger.domain.clock import NS_PER_SECOND, from_ns, to_ns
from faultledger.domain.events import (
    KINDS,
    FaultCleared,
    FaultReported,
    GoalOutcome,
    LogRecord,
    goal_event_id,
)
from faultledger.domain.fault import Fault
from faultledger.domain.notifications import Notification
from faultledger.domain.periods import default_calendar
from faultledger.domain.policy import Policy
from faultledger.domain.projector import Projector, Transition
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import DEFAULT_ESTOP_CODES, StatsRow
from faultledger.domain.statistics import StatsFold
from faultledger.errors import (
    DamagedDatabaseError,
    FaultLedgerError,
    InvalidInputError,
    Reason,
)
from faultledger.service import statistics
from faultledger.service.requests import GoalOutcomeRequest, ReportRequest
from faultledger.service.results import (
    ClearResult,
    Downtime,
    EntityLookup,
    FaultLookup,
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
    ReclassifyHealed,
    RecordGoal,
    RecordPolicy,
    Report,
    Writer,
    clipped,
)
from faultledger.store import event_log, integrity_check, migrate, projections, stat_tables
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
                 max_batch: int, restored: Restored) -> None:
        self._db = db
        self._subscriptions: list[Subscription] = []
        self._subscriptions_lock = threading.Lock()
        self._writer = Writer(db, projector, policy, self._announce, max_batch)
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
             estop_codes: Sequence[str] | None = None) -> FaultLedger:
        """Open (create, migrate) the database and restore state: projections + log tail.

        With a ``policy`` this process is a serving writer: the policy is recorded when it
        differs from the log's, HEALED faults it cannot heal become CLEARED, and a background
        thread runs time-based confirmation. Without one, the log's own policy applies and
        opening writes nothing (unless ``upgrade`` has a migration to run).
        """
        db = Database(url, create=create)
        try:
            migrate.ensure_current(db, upgrade=upgrade)
            projector, restored = _restore(db)
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
        ledger = cls(db, projector, policy, max_batch, restored)
        if calendar is not None:
            ledger.calendar = calendar
        if estop_codes is not None:
            ledger.estop_codes = statistics.estop_globs(estop_codes)
        try:
            if policy is not None:
                ledger._writer.submit(RecordPolicy())
                ledger._writer.submit(ReclassifyHealed(policy))
            if background if background is not None else policy is not None:
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
    def last_seq(self) -> int:
        """The newest record whose effects readers see (not one still being committed)."""
        return self._writer.projector.committed_seq

    # -- writes ----------------------------------------------------------------------------------
    def report(self, fault_code: str, event_type: str | int, severity: int = 0,
               description: str = "", source_id: str = "", at: datetime | None = None,
               event_id: str | None = None) -> ReportResult:
        """Record one FAILED/PASSED report; returns once it is durable (or rejected)."""
        return self.report_many([ReportRequest(fault_code, event_type, severity, description,
                                               source_id, at, event_id)])[0]

    def report_many(self, requests: Sequence[ReportRequest]) -> list[ReportResult]:
        """Record several reports in order, sharing commits; one result per request.

        For a caller that receives reports in bursts (a ROS service draining its queue, a
        bridge translating one message into many reports): one wait instead of one per report.
        """
        return self._submit_checked([_report_command(request) for request in requests])

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
        return self._submit_checked([_goal_command(request) for request in requests])

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

    def run_timers(self, now: datetime | None = None) -> int:
        """Confirm PREFAILED faults whose last FAILED is ``auto_confirm_after_sec`` old."""
        now_ns = time.time_ns() if now is None else to_ns(now)
        count: int = self._writer.submit(ConfirmOverdue(now_ns))
        return count

    def rebuild(self) -> int:
        """Drop the projections and replay the whole log; returns the records replayed."""

        def action(conn: Connection, writer: Writer) -> int:
            projector, replayed = _replay(conn)
            projections.replace_all(conn, projector.committed(), replayed,
                                    projections.Checkpoint(*event_log.head(conn),
                                                           projector.policy_seq))
            stat_tables.replace_all(conn, _stats(projector).take(), projector.seq)
            writer.projector = projector
            return projector.seq

        count: int = self._writer.submit(Exclusive(action))
        return count

    # -- reads -----------------------------------------------------------------------------------
    def _faults(self) -> list[Fault]:
        return self._writer.projector.committed()

    def list_faults(self, statuses: Iterable[str] = (), severity: int | None = None
                    ) -> list[Fault]:
        return queries.select(self._faults(), statuses, severity)

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
        where = _record_filter(code, since, until, source, kinds, limit, codes, from_seq, to_seq)
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
        return statistics.compute(self._db, query)

    def downtimes(self, since: datetime, until: datetime, limit: int | None = None, *,
                  as_of: datetime | None = None) -> list[Downtime]:
        """The CONFIRMED episodes overlapping [since, until), most time inside the range
        first (then the longest, then the earliest).

        An episode still open ends at ``as_of`` (default now), as in ``stats``; episodes
        with no time inside the range (0 s, or starting after ``as_of``) are left out.
        """
        since_ns, until_ns = _aware_ns(since, "since"), _aware_ns(until, "until")
        as_of_ns = time.time_ns() if as_of is None else _aware_ns(as_of, "as_of")
        _check_limit(limit)
        if since_ns >= until_ns:
            raise InvalidInputError("since must be before until")
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
        with self._db.reading() as conn:
            return projections.load_transitions(conn, code)

    def state_at(self, when: datetime | int) -> list[Fault]:
        """Faults (any status) after the log prefix up to seq ``when``, or recorded by a time."""
        upto = _seq(when, "when") if isinstance(when, int) else _aware_ns(when, "when")
        with self._db.reading() as conn:
            if not isinstance(when, int):
                upto = event_log.last_seq_recorded_by(conn, upto)
            projector = Projector()
            try:
                _apply_all(projector, event_log.read(conn, upto_seq=upto))
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
        if from_seq is not None or to_seq is not None:
            return _verify_segment(self._db, 1 if from_seq is None else from_seq, to_seq)
        return _with_storage_damage(self._db, self._verify_log)

    def _verify_log(self) -> VerifyReport:
        with self._db.reading() as conn:
            chain = event_log.check_chain(conn)
            checkpoint = projections.load_checkpoint(conn)
            problems = [chain.problem] if chain.problem else []
            first_bad = chain.first_bad_seq
            if chain.problem is None:
                if checkpoint.seq > chain.head_seq:
                    first_bad = chain.head_seq + 1
                    problems.append(
                        f"the log ends at seq {chain.head_seq} but the projections include seq "
                        f"{checkpoint.seq}: records {chain.head_seq + 1}..{checkpoint.seq} were "
                        "deleted")
                elif checkpoint.seq == chain.head_seq and checkpoint.hash != chain.head_hash:
                    first_bad = chain.head_seq
                    problems.append(f"record {chain.head_seq} differs from the recorded head")
            if not problems:
                try:
                    problems.extend(_projection_problems(conn, checkpoint))
                except UnreadableRecord as error:  # its hash matches: rehashed, or written so
                    first_bad = error.seq
                    problems.append(f"{error}: {DAMAGED} (its hash and those after it match: "
                                    "they were recomputed, or it was written so)")
        return VerifyReport(not problems, chain.records, chain.head_seq, chain.head_hash,
                            first_bad, problems)

    # -- notifications ---------------------------------------------------------------------------
    def notifications_after(self, seq: int, limit: int = 1000) -> list[Notification]:
        """The announcements of the records after ``seq``, as subscribers received them (at
        most ``limit``, in seq order), derived from the log: how a stream client that was
        away (or a restarted server) catches up with nothing missed and nothing twice.

        Only the faults those records touch are replayed, unless there are very many.
        """
        seq = _seq(seq, "seq")
        _check_limit(limit)
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
                with self._db.reading() as conn:
                    stored = event_log.head(conn)[0]
                if stored != self.last_seq:
                    self._writer.submit(CatchUp())
                if self.policy.auto_confirm_after_sec > 0:
                    self._writer.submit(ConfirmOverdue(time.time_ns()))
            except FaultLedgerError as error:
                log.warning("background check failed: %s", error)

    def _tick_interval(self) -> float:
        after = self.policy.auto_confirm_after_sec
        return 1.0 if after <= 0 else min(1.0, max(0.05, after / 10))


def _canonical_event_id(event_id: object) -> str | None:
    """The one spelling of a UUID the log stores and the idempotency check compares: lowercase
    and hyphenated. Every spelling ``uuid.UUID`` reads (upper case, ``{…}``, ``urn:uuid:…``,
    no hyphens) is the same report. None: not a UUID."""
    if not isinstance(event_id, str) or len(event_id) > 64:
        return None
    try:
        return str(uuid.UUID(event_id))
    except ValueError:
        return None


DAMAGED = "its content is damaged or was edited"


class UnreadableRecord(Exception):
    """A stored record this code cannot decode or apply: a damaged or edited payload (valid
    records never fail a replay), named by its seq."""

    def __init__(self, seq: int, error: BaseException) -> None:
        super().__init__(f"record seq {seq} cannot be read back ({clipped(error, 200)})")
        self.seq = seq


def _apply_all(projector: Projector, records: Iterable[LogRecord]) -> list[Transition]:
    """``projector.apply_all`` over consecutive records; a record that cannot be decoded (in
    the store's read) or applied raises UnreadableRecord with its seq. Database errors
    (locked, I/O) pass unchanged."""
    reading = iter(records)

    def checked() -> Iterator[LogRecord]:
        while True:
            try:
                record = next(reading)
            except StopIteration:
                return
            except FaultLedgerError:
                raise
            except Exception as error:  # decoding the next record failed
                raise UnreadableRecord(projector.seq + 1, error) from error
            yield record

    try:
        return projector.apply_all(checked())
    except (UnreadableRecord, FaultLedgerError):
        raise
    except Exception as error:  # applying the record projector.seq failed
        raise UnreadableRecord(projector.seq, error) from error


def _replay(conn: Connection, upto: int | None = None) -> tuple[Projector, list[Transition]]:
    projector = Projector(stats=StatsFold())
    return projector, _apply_all(projector, event_log.read(conn, upto_seq=upto))


def _stats(projector: Projector) -> StatsFold:
    assert projector.stats is not None, "this projector feeds no statistics"
    return projector.stats


def _restore(db: Database) -> tuple[Projector, Restored]:
    """Persisted projections plus a replay of the records after their checkpoint."""
    with db.reading() as conn:
        checkpoint = projections.load_checkpoint(conn)
        policy = event_log.policy_at(conn, checkpoint.policy_seq)
        stats_seq = stat_tables.checkpoint_seq(conn)
        tracks = stat_tables.load_tracks(conn) if stats_seq == checkpoint.seq else None
        projector = Projector(
            projections.load_faults(conn),
            Policy.model_validate(policy.policy) if policy else None,
            checkpoint.seq,
            policy_recorded=policy is not None,
            policy_seq=checkpoint.policy_seq,
            stats=StatsFold(tracks),
        )
        stored_seq = event_log.head(conn)[0]
    if tracks is None:
        projector.stats = _catch_up_statistics(db, checkpoint.seq, stats_seq)
    if stored_seq < checkpoint.seq:
        log.warning("the log ends at seq %d but the projections include seq %d: records were "
                    "deleted; writes are refused (run `faultledger verify`)",
                    stored_seq, checkpoint.seq)
    replayed = max(0, stored_seq - checkpoint.seq)
    if replayed:
        projector = _persist_tail(db, projector)
    faults = len(projector.committed())
    return projector, Restored(stored_seq, faults, replayed)


def _persist_tail(db: Database, projector: Projector) -> Projector:
    """Bring lagging projections up to the log (in memory, and on disk when writable)."""
    try:
        with db.writing() as conn:
            projector.stage()
            found = _apply_all(projector, event_log.read(conn, after_seq=projector.seq))
            projections.save(conn, projector.staged_faults(), found,
                             projections.Checkpoint(*event_log.head(conn), projector.policy_seq))
            stat_tables.save(conn, _stats(projector).take(), projector.seq)
        projector.commit()
    except FaultLedgerError as error:
        projector.rollback()
        log.warning("projections lag the log and cannot be saved (%s); replaying in memory",
                    error)
        with db.reading() as conn:
            _apply_all(projector, event_log.read(conn, after_seq=projector.seq))
        _stats(projector).take()
    return projector


def _catch_up_statistics(db: Database, upto: int, stats_seq: int) -> StatsFold:
    """Statistics tables behind the projections (first open after the upgrade that created
    them): fold the log up to the projections' seq and write them all."""
    with db.reading() as conn:
        replayed = Projector(stats=StatsFold())
        _apply_all(replayed, event_log.read(conn, upto_seq=upto))
    fold = _stats(replayed)
    output = fold.take()
    log.info("statistics include seq %d of %d: computing them from the log", stats_seq, upto)
    try:
        with db.writing() as conn:
            stat_tables.replace_all(conn, output, upto)
    except FaultLedgerError as error:
        log.warning("statistics cannot be saved (%s); they are incomplete until a writer "
                    "opens this database", error)
    return StatsFold(fold.tracks())


def _projection_problems(conn: Connection, checkpoint: projections.Checkpoint) -> list[str]:
    expected, expected_transitions = _replay(conn, checkpoint.seq)
    stored = projections.load_faults(conn)
    problems: list[str] = []
    replayed = {f.fault_code: f for f in expected.committed()}
    for code in sorted(set(stored) | set(replayed)):
        if stored.get(code) != replayed.get(code):
            problems.append(f"projection of fault {code} differs from a full replay of the log")
    if projections.load_transitions(conn) != expected_transitions:
        problems.append("transitions table differs from a full replay of the log")
    if stat_tables.checkpoint_seq(conn) == checkpoint.seq:
        problems.extend(stat_tables.differences(conn, _stats(expected).take()))
    else:
        problems.append(f"statistics include seq {stat_tables.checkpoint_seq(conn)}, the "
                        f"projections {checkpoint.seq}")
    if checkpoint.policy_seq != expected.policy_seq:
        problems.append(f"checkpoint names record {checkpoint.policy_seq} as the policy in force, "
                        f"a replay finds {expected.policy_seq}")
    return problems


def _report_command(request: ReportRequest) -> Report | ReportResult:
    """The writer's command for a valid report, else the rejection naming the problem.

    Every field is checked here, before the report joins a group commit: one bad report must
    never fail the commit it would share with valid ones (the writer isolates one that
    still does, as a last resort).
    """
    if not isinstance(request, ReportRequest):
        return ReportResult(False, f"expected a ReportRequest, got {type(request).__name__}")
    kind = validation.parse_event_type(request.event_type)
    problem = validation.report_error(request.fault_code, request.event_type, request.severity,
                                      request.description, request.source_id)
    event_id = None
    if problem is None and request.event_id is not None:
        event_id = _canonical_event_id(request.event_id)
        if event_id is None:
            problem = f"event_id must be a UUID, got {validation.shown(request.event_id)}"
    if problem is None and request.at is not None:
        problem = validation.time_error("at", request.at)
    if problem is not None or kind is None:
        return ReportResult(False, problem or "invalid report")
    occurred_ns = time.time_ns() if request.at is None else to_ns(request.at)
    event = FaultReported(request.fault_code, kind, request.severity, request.description,
                          request.source_id)
    return Report(event, occurred_ns, event_id or str(uuid.uuid4()), event_id is not None)


def _goal_command(request: GoalOutcomeRequest) -> RecordGoal | ReportResult:
    """The writer's command for a valid goal outcome, else the rejection naming the problem
    (checked before it joins a group commit, like a report)."""
    if not isinstance(request, GoalOutcomeRequest):
        return ReportResult(False, f"expected a GoalOutcomeRequest, got {type(request).__name__}")
    problem = validation.goal_outcome_error(request.action, request.goal_id, request.status,
                                            request.server_node)
    if problem is None and request.at is not None:
        problem = validation.time_error("at", request.at)
    if problem is not None:
        return ReportResult(False, problem)
    occurred_ns = time.time_ns() if request.at is None else to_ns(request.at)
    event = GoalOutcome(request.action, request.goal_id, request.status, request.server_node)
    return RecordGoal(event, occurred_ns, goal_event_id(request.action, request.goal_id))


# -- audit: filtered and streamed history, verification of a segment, prefixes by time -------
def export_history(ledger: FaultLedger, code: str | None = None,
                   since: datetime | int | None = None, until: datetime | int | None = None,
                   source: str | None = None, kinds: Iterable[str] = (),
                   limit: int | None = None, *, codes: Sequence[str] | None = None,
                   from_seq: int | None = None, to_seq: int | None = None,
                   descending: bool = False) -> Iterator[event_log.StoredRecord]:
    """``history``'s selection as stored rows with their predecessor's hash, streamed
    (``descending``: newest first, and ``limit`` keeps the newest).

    For exports of any size: rows are fetched in chunks inside one read transaction while the
    caller consumes them (a consistent snapshot). The filter is checked here, before the
    first row, so bad input fails before anything is written.
    """
    where = _record_filter(code, since, until, source, kinds, limit, codes, from_seq, to_seq)
    return _stored_rows(ledger._db, replace(where, descending=descending))


def count_history(ledger: FaultLedger, code: str | None = None,
                  since: datetime | int | None = None, until: datetime | int | None = None,
                  source: str | None = None, kinds: Iterable[str] = (), *,
                  codes: Sequence[str] | None = None, from_seq: int | None = None,
                  to_seq: int | None = None) -> int:
    """How many records ``history`` selects with these filters (no limit)."""
    where = _record_filter(code, since, until, source, kinds, None, codes, from_seq, to_seq)
    with ledger._db.reading() as conn:
        return event_log.count_matching(conn, where)


def _stored_rows(db: Database, where: event_log.RecordFilter
                 ) -> Iterator[event_log.StoredRecord]:
    with db.reading() as conn:
        yield from event_log.iter_stored(conn, where)


def seq_recorded_by(ledger: FaultLedger, when: datetime | int) -> int:
    """The last seq of the log prefix ``state_at(when)`` replays, so it can be named and
    verified: a seq is checked against the log, a time maps to the records recorded by it."""
    with ledger._db.reading() as conn:
        if isinstance(when, int):
            when = _seq(when, "seq")
            head_seq = event_log.head(conn)[0]
            if not 0 <= when <= head_seq:
                raise InvalidInputError(f"seq {when} is not in the log (seq 0..{head_seq})")
            return when
        return event_log.last_seq_recorded_by(conn, _aware_ns(when, "when"))


def seqs_recorded_between(ledger: FaultLedger, since: datetime | None,
                          until: datetime | None) -> tuple[int, int | None]:
    """Inclusive seq range of the records recorded in [since, until]: a contiguous segment
    that ``verify`` can check (``occurred_at`` is the reporter's and not in seq order).

    ``until`` ends where ``state_at(until)``'s prefix ends; None means up to the head.
    """
    with ledger._db.reading() as conn:
        start = 1 if since is None else event_log.last_seq_recorded_by(
            conn, _aware_ns(since, "since") - 1) + 1
        end = None if until is None else event_log.last_seq_recorded_by(
            conn, _aware_ns(until, "until"))
        head_seq = event_log.head(conn)[0]
    if start > (head_seq if end is None else end):
        window = " and ".join(f"{name} {moment.isoformat()}" for name, moment
                              in (("since", since), ("until", until)) if moment is not None)
        raise InvalidInputError(f"no record of the log (seq 1..{head_seq}) was recorded within "
                                f"{window}")
    return start, end


def _with_storage_damage(db: Database, check: Callable[[], VerifyReport]) -> VerifyReport:
    """``check`` after the database's own integrity check; damage fails the report. A damaged
    file may also break the check itself: then the damage and that error are the report."""
    with db.reading() as conn:
        damage = integrity_check.storage_damage(conn)
    if not damage:
        return check()
    try:
        report = check()
    except Exception as error:  # any failure reading a file known to be damaged
        return VerifyReport(False, 0, 0, "", None,
                            [*damage, f"the log could not be checked: {error}"])
    return VerifyReport(False, report.records, report.head_seq, report.head_hash,
                        report.first_bad_seq, [*damage, *report.problems])


def _verify_segment(db: Database, from_seq: int, to_seq: int | None) -> VerifyReport:
    """``verify`` over [from_seq, to_seq]: the chain segment and the checkpoint inside it."""
    _check_seq_range(from_seq, to_seq)
    with db.reading() as conn:
        chain = event_log.check_chain(conn, from_seq, to_seq)
        problems = [chain.problem] if chain.problem else []
        first_bad = chain.first_bad_seq
        if chain.problem is None:
            found = _checkpoint_problem(conn, from_seq, to_seq, chain)
            if found is not None:
                first_bad = found[0]
                problems.append(found[1])
    return VerifyReport(not problems, chain.records, chain.head_seq, chain.head_hash, first_bad,
                        problems)


def _checkpoint_problem(conn: Connection, from_seq: int, to_seq: int | None,
                        chain: event_log.ChainCheck) -> tuple[int, str] | None:
    """The checkpoint names (seq, hash) of a record: it must exist and match when the verified
    segment is open-ended or holds that seq (catches a rewritten head with a fresh hash)."""
    checkpoint = projections.load_checkpoint(conn)
    if to_seq is None and checkpoint.seq > chain.head_seq:
        return chain.head_seq + 1, (
            f"the log ends at seq {chain.head_seq} but the projections include seq "
            f"{checkpoint.seq}: records {chain.head_seq + 1}..{checkpoint.seq} were deleted")
    if (from_seq <= checkpoint.seq <= chain.head_seq
            and event_log.hash_at(conn, checkpoint.seq) != checkpoint.hash):
        return checkpoint.seq, f"record {checkpoint.seq} differs from the recorded head"
    return None


def _record_filter(code: str | None, since: datetime | int | None, until: datetime | int | None,
                   source: str | None, kinds: Iterable[str], limit: int | None,
                   codes: Sequence[str] | None, from_seq: int | None, to_seq: int | None
                   ) -> event_log.RecordFilter:
    """A checked history filter: bad input is an InvalidInputError naming it, never a silently
    empty answer (a misspelt kind would otherwise look like "nothing happened")."""
    wanted = _strings(kinds, "kinds")
    unknown = [kind for kind in wanted if kind not in KINDS]
    if unknown:
        named = ", ".join(validation.shown(kind, 40) for kind in unknown[:5])
        raise InvalidInputError(f"unknown record kind {named}; valid "
                                f"kinds: {', '.join(KINDS)}")
    patterns = _strings(codes, "codes")
    if len(patterns) > statistics.MAX_PATTERNS:
        raise InvalidInputError(f"codes takes at most {statistics.MAX_PATTERNS} patterns")
    for name, value, size in (*(("a code pattern", c, statistics.MAX_PATTERN_LENGTH)
                                for c in patterns),
                              ("code", code, validation.MAX_FAULT_CODE_LENGTH),
                              ("source", source, validation.MAX_SOURCE_ID_LENGTH)):
        problem = None if value is None else validation.text_error(name, value, size)
        if problem:
            raise InvalidInputError(problem)
    _check_seq_range(from_seq, to_seq)
    _check_limit(limit)
    return event_log.RecordFilter(
        fault_code=code, source_id=source, since_ns=_bound_ns(since, "since"),
        until_ns=_bound_ns(until, "until"), kinds=wanted, limit=limit, codes=patterns,
        from_seq=from_seq, to_seq=to_seq,
    )


def _strings(value: Iterable[str] | str | None, name: str) -> tuple[str, ...]:
    """One string or a collection of them as a tuple; anything else is refused by name."""
    if value is None:
        return ()
    if isinstance(value, str):
        return (value,)
    if not isinstance(value, list | tuple | set | frozenset) or len(value) > 10_000 or not all(
            isinstance(item, str) for item in value):
        raise InvalidInputError(f"{name} must be a list of strings, got "
                                f"{validation.shown(value)}")
    return tuple(value)


def _check_limit(limit: int | None) -> None:
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int)
                              or not 0 <= limit <= validation.MAX_INTEGER):
        raise InvalidInputError(f"limit must be a whole number of 0 or more, got "
                                f"{validation.shown(limit)}")


def _seq(value: int, name: str) -> int:
    if (isinstance(value, bool) or not isinstance(value, int)
            or not 0 <= value <= validation.MAX_INTEGER):
        raise InvalidInputError(f"{name} must be a seq number of 0 or more, got "
                                f"{validation.shown(value)}")
    return value


def _check_seq_range(from_seq: int | None, to_seq: int | None) -> None:
    for name, value in (("from_seq", from_seq), ("to_seq", to_seq)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or not 1 <= value <= validation.MAX_INTEGER):
            raise InvalidInputError(f"{name} must be a seq number of 1 or more, got {value!r}")
    if from_seq is not None and to_seq is not None and from_seq > to_seq:
        raise InvalidInputError(f"from_seq {from_seq} is after to_seq {to_seq}: the range is "
                                "empty")


def _bound_ns(moment: datetime | int | None, name: str) -> int | None:
    if moment is None:
        return None
    if isinstance(moment, datetime):
        return _aware_ns(moment, name)
    problem = validation.ns_error(name, moment)
    if problem:
        raise InvalidInputError(problem)
    return moment


def _aware_ns(moment: datetime, name: str) -> int:
    """A datetime argument as nanoseconds; InvalidInputError unless the log can hold it."""
    problem = validation.time_error(name, moment)
    if problem:
        raise InvalidInputError(problem)
    return to_ns(moment)
