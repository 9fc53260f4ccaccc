"""Store and forward, the robot's half (docs/fleet.md, "Robot side"): push every record of the
robot's log, verbatim and in seq order, to the central, in batches of at most 1,000 records,
sized to the central's pace (fleet/pace.py).

``Pusher.sync`` catches up once (`faultledger sync`); ``Pusher.follow`` keeps the central
caught up until stopped (`sync --follow`, and ``PusherThread`` in `serve` / `http` with the
config's ``fleet:``). Both start by asking where the central stands (an empty batch) and push
from its ``last_seq + 1``: whatever happened before (a sync killed mid-batch, a lost answer,
a central restored from a backup) the central's answer is the only state, so nothing is
skipped and nothing is stored twice (a batch sent again is ignored by the central when
identical). The robot's log is only read.
"""

from __future__ import annotations

import json
import logging
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, TypeVar

from faultledger.domain.identity import LedgerIdentity
from faultledger.domain.text import printable
from faultledger.errors import FaultLedgerError, Reason
from faultledger.fleet.client import (
    BatchRefused,
    BatchTooLarge,
    CentralClient,
    CentralError,
    ChainGap,
    PushAnswer,
    TokenRefused,
    read_token,
)
from faultledger.fleet.pace import BatchPace
from faultledger.service.audit import export_history
from faultledger.service.config import FleetSettings
from faultledger.service.ledger import FaultLedger
from faultledger.store.database import describe
from faultledger.store.event_log import StoredRecord

log = logging.getLogger(__name__)

MAX_RECORDS = 1000
"""Records per batch: the protocol's limit."""
MAX_BATCH_BYTES = 900 * 1024
"""A batch is cut before its body passes this, under the central's default
``http.max_body_bytes`` (1 MiB); a 413 halves it (a central with a smaller limit)."""
POLL_SEC = 0.2
"""Following: how often the log's head is looked at (one indexed read), so a new record is
pushed well within a second of its commit."""
CONTACT_SEC = 5.0
"""Following and idle: an empty batch this often, the contact that keeps the central's
lag_seconds small (docs/fleet.md, "Lag")."""
BACKOFF_FIRST_SEC = 0.5
BACKOFF_MAX_SEC = 30.0
"""Following: waits while the central is away or answers 5xx, doubling up to this (a
Retry-After the central gives is honoured instead)."""
REFUSED_RETRY_SEC = 60.0
"""Following: after a refusal (a record differs, a broken chain, a refused token) the same
batch is tried again this rarely: it will be refused again until a person acts, but it is
never skipped."""
NO_IDENTITY_RETRY_SEC = 1.0
"""Following a log without identity yet (nothing written): look again this often."""
ONE_SHOT_WAITS = (0.5, 1.0, 2.0)
"""`sync` without --follow: waits before trying a request again while the central is away
or busy, then it gives up (exit 1)."""
ONE_SHOT_MAX_RETRY_AFTER_SEC = 10.0
"""`sync` without --follow waits out a Retry-After up to this; a longer one ends it."""
PROGRESS_SEC = 10.0
"""``LogReporter``: a progress line at most this often while a backlog is pushed."""

T = TypeVar("T")


class RobotLogError(FaultLedgerError):
    """The robot's log cannot be pushed as it is: it has no identity yet, a record is missing
    from it, or it holds less than the central already has (a truncated log)."""

    def __init__(self, message: str, seq: int | None = None,
                 retry_sec: float = REFUSED_RETRY_SEC) -> None:
        super().__init__(message)
        self.seq = seq
        self.retry_sec = retry_sec


class NoIdentityError(RobotLogError):
    """The log records no robot_id / ledger_id yet: no writer has written to it."""


class Stopped(FaultLedgerError):
    """``Pusher.sync`` was stopped (a signal) before it caught up."""

    reason = Reason.UNAVAILABLE


def record_json(record: StoredRecord) -> str:
    """One record of a batch as the protocol sends it: every stored field, ``payload`` the
    stored canonical text (the hash covers it byte for byte) and ``prev_hash`` as stored."""
    return json.dumps({
        "seq": record.seq, "event_id": record.event_id, "kind": record.kind,
        "fault_code": record.fault_code, "source_id": record.source_id,
        "payload": record.payload_json, "occurred_at_ns": record.occurred_at_ns,
        "recorded_at_ns": record.recorded_at_ns, "schema_version": record.schema_version,
        "hash": record.hash, "prev_hash": record.prev_hash,
    }, ensure_ascii=False, separators=(",", ":"))


@dataclass(frozen=True, slots=True)
class Batch:
    """Consecutive records of the log, encoded, with what the lag needs."""

    records: list[str]
    first_seq: int
    last_seq: int
    last_recorded_ns: int

    def first(self, count: int, last_recorded_ns: int) -> Batch:
        return Batch(self.records[:count], self.first_seq, self.first_seq + count - 1,
                     last_recorded_ns)


def _first(rows: Iterator[StoredRecord]) -> StoredRecord | None:
    """The first row, closing the read (its transaction) at once."""
    try:
        return next(rows, None)
    finally:
        close = getattr(rows, "close", None)
        if close is not None:
            close()


class RobotLog:
    """The robot's log as the pusher reads it: through the service, rows as stored."""

    def __init__(self, ledger: FaultLedger) -> None:
        self.ledger = ledger

    def identity(self) -> LedgerIdentity:
        """The log's identity; ``NoIdentityError`` when it records none yet."""
        found = self.ledger.identity
        if found is None:
            head = self.head()
            what = ("it is empty" if head == 0 else
                    f"it holds {head} records written before identities: the next writer "
                    "(serve, a report) records them")
            raise NoIdentityError(f"the log {describe(self.ledger.url)} records no robot_id and "
                                  f"ledger_id yet ({what}); there is nothing a central could "
                                  "file it under", retry_sec=NO_IDENTITY_RETRY_SEC)
        return found

    def head(self) -> int:
        """The newest seq in the log, 0 when empty: one indexed read."""
        newest = _first(export_history(self.ledger, descending=True, limit=1))
        return 0 if newest is None else newest.seq

    def recorded_ns(self, seq: int) -> int | None:
        """When record ``seq`` was recorded (for the lag); None when the log lacks it."""
        if seq < 1:
            return None
        found = _first(export_history(self.ledger, from_seq=seq, to_seq=seq))
        return None if found is None else found.recorded_at_ns

    def hashes(self, first: int, last: int) -> dict[int, str]:
        """The stored hash of every record the log holds in ``first..last``."""
        return {record.seq: record.hash
                for record in export_history(self.ledger, from_seq=first, to_seq=last)}

    def batch(self, after: int, max_records: int, max_bytes: int) -> Batch | None:
        """The records after seq ``after``, at most ``max_records`` and about ``max_bytes`` of
        body (at least one); None when there are none. A batch ends before a record missing
        from the log (a seq skipped, a deleted predecessor); a batch that would start with
        one is a ``RobotLogError`` naming it: no batch may jump."""
        encoded: list[str] = []
        size = 0
        last: StoredRecord | None = None
        rows = export_history(self.ledger, from_seq=after + 1, limit=max_records)
        try:
            for record in rows:
                expected = after + 1 + len(encoded)
                if (record.seq != expected or record.prev_hash is None) and encoded:
                    break  # push what comes before it; the next batch names it
                if record.seq != expected or record.prev_hash is None:
                    missing = expected if record.seq != expected else record.seq - 1
                    raise RobotLogError(
                        f"record seq {missing} is missing from the log {describe(self.ledger.url)} "
                        f"(it goes on at seq {record.seq}): it was deleted or the log is "
                        f"damaged; nothing from seq {missing} on can be pushed (faultledger "
                        "verify)", missing)
                text = record_json(record)
                if encoded and size + len(text) + 1 > max_bytes:
                    break
                encoded.append(text)
                size += len(text) + 1
                last = record
        finally:
            close = getattr(rows, "close", None)
            if close is not None:
                close()
        if last is None:
            return None
        return Batch(encoded, after + 1, last.seq, last.recorded_at_ns)


@dataclass(frozen=True, slots=True)
class Status:
    """Where a push run stands, for progress lines."""

    identity: LedgerIdentity
    central: str
    central_seq: int
    head_seq: int
    start_seq: int
    """The central's seq when this run first learned it."""
    pushed: int
    """Records the central stored from this run."""
    ignored: int
    """Records the central already held, identical (sent again after a lost answer)."""
    rate: float
    """Records per second of the current catch-up (0 before one)."""
    lag_seconds: float
    """0 when caught up, else how old the newest record the central holds is (the central's
    own measure, docs/fleet.md "Lag"); the age of the oldest record when it holds none."""
    elapsed: float

    @property
    def behind(self) -> int:
        return max(0, self.head_seq - self.central_seq)

    @property
    def caught_up(self) -> bool:
        return self.central_seq >= self.head_seq


class Reporter(Protocol):
    """Where a push run says what it does: the CLI's progress, or the server's log."""

    def progress(self, status: Status) -> None:
        """After every answer of the central."""

    def event(self, level: int, text: str) -> None:
        """Something a person should read: the central away, back, a refusal."""


def log_line(level: int, text: str) -> None:
    """``LogReporter``'s default: the Python log."""
    log.log(level, "%s", text)


def print_line(level: int, text: str) -> None:
    """For a server's console (`serve`, `http`): information on stdout beside its ready
    lines, warnings and errors on stderr; one line each, flushed (a journal reads them)."""
    out = sys.stderr if level >= logging.WARNING else sys.stdout
    label = {logging.ERROR: "error: ", logging.WARNING: "warning: "}.get(level, "")
    print(f"fleet: {label}{printable(text)}", file=out, flush=True)


class LogReporter:
    """For a pusher inside a server: a line when a backlog starts, every ``PROGRESS_SEC``
    while it is pushed, when it is caught up, and every event; nothing while idle."""

    def __init__(self, say: Callable[[int, str], None] = log_line) -> None:
        self.say = say
        self._pushing = False
        self._said = 0.0

    def progress(self, status: Status) -> None:
        now = time.monotonic()
        if not status.caught_up and not self._pushing:
            self._pushing = True
            self._said = now
            self.say(logging.INFO, f"pushing {status.behind} records to {status.central} "
                     f"(seq {status.central_seq + 1}..{status.head_seq})")
        elif not status.caught_up and now - self._said >= PROGRESS_SEC:
            self._said = now
            self.say(logging.INFO, f"{status.central} at seq {status.central_seq} of "
                     f"{status.head_seq}, {status.rate:,.0f} records/s, lag "
                     f"{status.lag_seconds:.0f} s")
        elif status.caught_up and self._pushing:
            self._pushing = False
            self.say(logging.INFO, f"caught up: {status.central} holds seq "
                     f"{status.central_seq} ({status.pushed} records pushed since start)")

    def event(self, level: int, text: str) -> None:
        self.say(level, text)


class Pusher:
    """Pushes one robot log to one central (see the module's docstring)."""

    def __init__(self, robot_log: RobotLog, client: CentralClient, reporter: Reporter, *,
                 max_records: int = MAX_RECORDS, max_bytes: int = MAX_BATCH_BYTES,
                 clock: Callable[[], float] = time.monotonic,
                 token_file: Path | None = None) -> None:
        self.log = robot_log
        self.token_file = token_file
        """Read again after the central refused the token (following): a token replaced in
        the file is used without a restart."""
        self.client = client
        self.reporter = reporter
        self.max_records = max(1, min(max_records, MAX_RECORDS))
        self.pace = BatchPace(self.max_records)
        self.max_bytes = max_bytes
        self.clock = clock
        self.stop = threading.Event()
        """Set by a signal or ``PusherThread.stop``: every wait ends at once."""
        self.central_seq: int | None = None
        """The central's last seq for this log, as its last answer said; None: ask first."""
        self.start_seq: int | None = None
        self.head_seq = 0
        self.pushed = 0
        self.ignored = 0
        self.started = clock()
        self.last_contact = -1e18
        self._held_ns: int | None = None
        """recorded_at of the newest record the central holds (for the lag)."""
        self._burst: tuple[float, int] | None = None
        """(start, pushed then) of the current catch-up, for its rate."""

    # -- one request each --------------------------------------------------------------------
    def ask(self) -> int:
        """An empty batch: where the central stands for this log (and contact)."""
        identity = self.log.identity()
        head = self.log.head()
        answer = self.client.push(identity.robot_id, identity.ledger_id, head)
        if answer.last_seq > head:
            raise RobotLogError(
                f"the central {self.client.shown} holds this log (ledger_id "
                f"{identity.ledger_id}) up to seq {answer.last_seq}, but it ends at seq {head} "
                f"here: records were removed from the robot's log (faultledger verify "
                f"--central names the first one)", head + 1)
        self._answered(identity, answer, head, None)
        return answer.last_seq

    def push_next(self) -> int:
        """Push the next batch after the central's last seq; the number of records sent."""
        if self.central_seq is None:
            self.ask()
        assert self.central_seq is not None
        identity = self.log.identity()
        if self._burst is None:
            self._burst = (self.clock(), self.pushed)
        head = self.log.head()
        batch = self.log.batch(self.central_seq, self.pace.size, self.max_bytes)
        if batch is None:
            return 0
        try:
            sent = self.clock()
            batch, answer = self._send(identity, head, batch)
            self.pace.answered(len(batch.records), self.clock() - sent)
        except BatchRefused as refusal:
            # The records before the refused one are good: the central takes them, so it
            # holds everything up to the seq named (a refusal stores nothing of its batch).
            seq = refusal.seq
            if seq is None or not batch.first_seq < seq <= batch.last_seq:
                raise
            good = seq - batch.first_seq
            prefix = batch.first(good, self.log.recorded_ns(seq - 1) or batch.last_recorded_ns)
            prefix, answer = self._send(identity, head, prefix)
            self._answered(identity, answer, max(head, prefix.last_seq), prefix)
            raise
        self._answered(identity, answer, max(head, batch.last_seq), batch)
        return len(batch.records)

    def _send(self, identity: LedgerIdentity, head: int, batch: Batch
              ) -> tuple[Batch, PushAnswer]:
        """POST ``batch``; a 413 halves it (and the byte budget of later ones) until the
        central takes it. Returns the batch the central took, with its answer."""
        while True:
            try:
                return batch, self.client.push(identity.robot_id, identity.ledger_id,
                                               max(head, batch.last_seq), batch.records)
            except BatchTooLarge as error:
                if len(batch.records) == 1:
                    raise BatchRefused(f"record seq {batch.first_seq} alone is larger than the "
                                       f"central accepts: {error}", 413, "too-large",
                                       batch.first_seq) from None
                self.max_bytes = max(1024, min(self.max_bytes,
                                               sum(len(r) for r in batch.records)) // 2)
                count = len(batch.records) // 2
                batch = batch.first(count, self.log.recorded_ns(batch.first_seq + count - 1)
                                    or batch.last_recorded_ns)
                self.reporter.event(logging.INFO, f"the central refused a batch as too large "
                                    f"(413): sending at most {self.max_bytes} bytes a batch")

    def _answered(self, identity: LedgerIdentity, answer: PushAnswer, head: int,
                  batch: Batch | None) -> None:
        """Take the central's answer as the state, and report it."""
        self.last_contact = self.clock()
        if self.start_seq is None:
            self.start_seq = answer.last_seq
        if batch is not None and answer.last_seq == batch.last_seq:
            self._held_ns = batch.last_recorded_ns
        elif answer.last_seq != self.central_seq:
            self._held_ns = self.log.recorded_ns(answer.last_seq)
        self.central_seq = answer.last_seq
        self.head_seq = max(head, answer.last_seq)
        self.pushed += answer.stored
        self.ignored += answer.ignored
        status = self.status(identity)
        if status.caught_up:
            self._burst = None
        self.reporter.progress(status)

    def status(self, identity: LedgerIdentity) -> Status:
        now = self.clock()
        central = self.central_seq or 0
        rate = 0.0
        if self._burst is not None and now > self._burst[0]:
            rate = (self.pushed - self._burst[1]) / (now - self._burst[0])
        lag = 0.0
        if central < self.head_seq:
            held = self._held_ns if central > 0 else self.log.recorded_ns(1)
            lag = 0.0 if held is None else max(0.0, time.time() - held / 1e9)
        return Status(identity, self.client.shown, central, self.head_seq,
                      self.start_seq or 0, self.pushed, self.ignored, rate, lag,
                      now - self.started)

    # -- `faultledger sync` ------------------------------------------------------------------
    def sync(self) -> Status:
        """Catch up once: ask, then push batches until the central holds the log's head.
        Refusals and a central still away after a few tries raise (exit 1)."""
        self._retrying(self.ask)
        gaps = 0
        while True:
            if self.stop.is_set():
                raise Stopped(f"stopped before catching up: the central holds seq "
                              f"{self.central_seq} of {self.head_seq}")
            assert self.central_seq is not None
            if self.central_seq >= self.log.head():
                return self.status(self.log.identity())
            try:
                self._retrying(self.push_next)
            except ChainGap as gap:  # the central lost records (restored): from its last seq
                gaps += 1
                if gaps > 3:
                    raise
                self.reporter.event(logging.WARNING, f"{gap}: pushing from seq "
                                    f"{gap.last_seq + 1}")
                self.central_seq = gap.last_seq

    def _retrying(self, action: Callable[[], T]) -> T:
        for wait in (*ONE_SHOT_WAITS, None):
            try:
                return action()
            except CentralError as error:
                if not error.transient or wait is None or self.stop.is_set():
                    raise
                delay = wait if error.retry_after is None else error.retry_after
                if delay > ONE_SHOT_MAX_RETRY_AFTER_SEC:
                    raise
                self.reporter.event(logging.WARNING, f"{error}; trying again in {delay:g} s")
                self.stop.wait(delay)
        raise AssertionError("unreachable")

    # -- `sync --follow`, serve's `fleet:` ---------------------------------------------------
    def follow(self) -> None:
        """Keep the central caught up until ``stop`` is set: a new record is pushed within
        about ``POLL_SEC`` plus one request; idle, an empty batch every ``CONTACT_SEC``. While
        the central is away or answers 5xx: exponential backoff (its Retry-After honoured);
        after a refusal: the same batch again every ``REFUSED_RETRY_SEC``, never skipped."""
        backoff = BACKOFF_FIRST_SEC
        trouble: str | None = None
        while not self.stop.is_set():
            try:
                if self.central_seq is None:
                    self.ask()
                elif self.central_seq < self.log.head():
                    self.push_next()
                elif self.clock() - self.last_contact >= CONTACT_SEC:
                    self.ask()
                else:
                    self.stop.wait(POLL_SEC)
                    continue
            except ChainGap as gap:
                self.reporter.event(logging.WARNING, f"{gap}: pushing from seq "
                                    f"{gap.last_seq + 1}")
                self.central_seq = gap.last_seq
                continue
            except CentralError as error:
                if error.transient:
                    delay = backoff if error.retry_after is None else error.retry_after
                    if trouble != "away":
                        self.reporter.event(logging.WARNING, f"{error}; trying again in "
                                            f"{delay:g} s, then less often (up to every "
                                            f"{BACKOFF_MAX_SEC:g} s); the log keeps every "
                                            "record")
                    trouble = "away"
                    backoff = min(backoff * 2, BACKOFF_MAX_SEC)
                    self.stop.wait(delay)
                else:
                    trouble = "refused"
                    self._refused(error, REFUSED_RETRY_SEC)
                continue
            except NoIdentityError as error:
                if trouble != "identity":
                    self.reporter.event(logging.INFO, f"{error}; waiting for the first record")
                trouble = "identity"
                self.stop.wait(error.retry_sec)
                continue
            except RobotLogError as error:
                trouble = "refused"
                self._refused(error, error.retry_sec)
                continue
            except FaultLedgerError as error:  # the robot's own database (locked, damaged)
                if trouble != "log":
                    self.reporter.event(logging.WARNING, f"cannot read the robot's log: "
                                        f"{error}; trying again")
                trouble = "log"
                self.stop.wait(backoff)
                backoff = min(backoff * 2, BACKOFF_MAX_SEC)
                continue
            if trouble is not None:
                self.reporter.event(logging.INFO, f"the central {self.client.shown} takes "
                                    f"records again; it holds seq {self.central_seq}")
                trouble = None
            backoff = BACKOFF_FIRST_SEC

    def _refused(self, error: FaultLedgerError, wait: float) -> None:
        """Say why nothing more is pushed, wait, and ask the central again afterwards (a
        refused token: with the token file read again)."""
        start = None if self.central_seq is None else self.central_seq + 1
        where = "" if start is None else f"; nothing from seq {start} on is pushed"
        self.reporter.event(logging.ERROR, f"{error}{where}; trying again in {wait:g} s")
        self.central_seq = None
        self.stop.wait(wait)
        if isinstance(error, TokenRefused) and self.token_file is not None:
            try:
                self.client.set_token(read_token(self.token_file))
            except FaultLedgerError as problem:
                self.reporter.event(logging.WARNING, str(problem))


class PusherThread:
    """``Pusher.follow`` on a thread of its own, beside a server (serve's or http's
    ``fleet:``); the server's ledger is only read. ``stop`` ends it within a request's time
    (the thread is a daemon: a hung central never holds up the process's exit)."""

    def __init__(self, pusher: Pusher) -> None:
        self.pusher = pusher
        self._thread: threading.Thread | None = None

    @classmethod
    def for_ledger(cls, ledger: FaultLedger, central: str, token_file: Path,
                   reporter: Reporter | None = None) -> PusherThread:
        """Read the token and check the URL now: a wrong one stops the server's start."""
        client = CentralClient(central, read_token(token_file))
        return cls(Pusher(RobotLog(ledger), client, reporter or LogReporter(),
                          token_file=token_file))

    @classmethod
    def start_for(cls, ledger: FaultLedger, settings: FleetSettings | None
                  ) -> PusherThread | None:
        """A server's pusher (the config's ``fleet:``), started; None without one. Its lines
        go to the server's console; a bad URL or token file is a ConfigError now."""
        if settings is None or settings.central is None or settings.token_file is None:
            return None  # no push configured (a central's fleet: has robot labels only)
        pusher = cls.for_ledger(ledger, settings.central, settings.token_file,
                                LogReporter(print_line))
        pusher.start()
        return pusher

    @property
    def describe(self) -> str:
        """The server's start line."""
        return f"fleet: pushing this log to {self.pusher.client.shown}"

    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="faultledger-fleet",
                                            daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self.pusher.stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
        self.pusher.client.close()

    def _run(self) -> None:
        while not self.pusher.stop.is_set():
            try:
                self.pusher.follow()
            except Exception as error:  # never let the pusher die silently
                log.error("fleet: the pusher failed: %s: %s; starting again in %g s",
                          type(error).__name__, error, REFUSED_RETRY_SEC)
                self.pusher.central_seq = None
                self.pusher.stop.wait(REFUSED_RETRY_SEC)
