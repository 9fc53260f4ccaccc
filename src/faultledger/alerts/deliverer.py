"""The deliverer of a serving process (`serve`, `faultledger http`): one thread scans the log
into the outbox, one thread per rule sends that rule's deliveries in order (docs/alerts.md).

Nothing runs on the report path: the ledger's subscription only sets an Event that wakes the
scanner, which reads the log itself from the rules' cursors. A receiver that is down holds up
only its own rule: its head is tried again with growing waits, and nothing behind it is sent
before it.
"""

from __future__ import annotations

import contextlib
import logging
import random
import threading
import time
from collections.abc import Callable, Iterator, Sequence

from faultledger.alerts.send import Outcome, Receiver
from faultledger.domain import alerts
from faultledger.domain.alerts import Alert
from faultledger.domain.clock import NS_PER_SECOND
from faultledger.service.alerts import AlertBook
from faultledger.service.config import AlertRule
from faultledger.service.ledger import FaultLedger, Subscription
from faultledger.store.alert_outbox import Delivery

log = logging.getLogger(__name__)

RENEW_SEC = 5.0
"""How often the leases are renewed (they last 15 s)."""
POLL_SEC = 1.0
"""The scanner looks at the log at least this often (records of other processes)."""
SCAN_GAP_SEC = 0.1
"""Least time between two scans: records arriving and answers received meanwhile share the
next scan's transaction (at most ten a second, beside the writer's)."""
BUSY_SCAN_GAP_SEC = 0.5
"""The same while ingest is busy: fewer, larger scans, fewer transactions beside the
writer's."""
CHECK_SEC = 5.0
"""How often stale faults and the fleet's lag are checked."""
ERROR_WAIT_SEC = 1.0
"""After a database error (locked, unavailable): wait, then go on."""
BATCH = 50
"""Deliveries a sender reads at once, and the most it has delivered that are not yet
recorded (what a crash could make a receiver see twice)."""
RECORD_GAP_SEC = 0.02
"""The least time between two scans while answers wait to be recorded and ingest is not
busy: a sender with a batch unrecorded waits for it."""


BUSY_RECORDS_PER_SEC = 500.0
"""The log grows faster than this: ingest is busy, and the deliverer yields to it."""
BUSY_SHARE = 0.03
"""While ingest is busy, the deliverer's threads together use at most this share of the
time (their own CPU time, measured): with the writer in the same interpreter, every
millisecond they spend is one the writer waits for (docs/performance.md, "Alerts")."""
MOST_DEBT_SEC = 0.05
MOST_CREDIT_SEC = 0.01


class Pace:
    """The deliverer's share of the interpreter while ingest is busy: a bucket of CPU time
    that fills at BUSY_SHARE of the wall clock; a thread that finds it empty waits (alerts
    lag behind a saturating burst, and catch up after it). While the log grows slowly
    nothing waits."""

    def __init__(self, ledger: FaultLedger, stop: threading.Event,
                 share: float = BUSY_SHARE) -> None:
        self._ledger = ledger
        self._stop = stop
        self._share = share
        self._lock = threading.Lock()
        self._credit = 0.0
        self._at = time.monotonic()
        self._seen = (self._at, ledger.last_seq)
        self._rate = 0.0

    def busy(self) -> bool:
        """Whether the log grew faster than BUSY_RECORDS_PER_SEC lately (sampled every
        0.2 s; one attribute read)."""
        with self._lock:
            now = time.monotonic()
            since, seq = self._seen
            if now - since >= 0.2:
                head = self._ledger.last_seq
                self._rate = (head - seq) / (now - since)
                self._seen = (now, head)
            return self._rate > BUSY_RECORDS_PER_SEC

    @contextlib.contextmanager
    def work(self) -> Iterator[None]:
        """Around one unit of work (a scan, a send): wait first while the bucket is empty
        and ingest busy; then take the CPU time the unit used."""
        while self.busy() and not self._stop.is_set():
            with self._lock:
                now = time.monotonic()
                self._credit = min(MOST_CREDIT_SEC,
                                   self._credit + (now - self._at) * self._share)
                self._at = now
                wait = -self._credit / self._share if self._credit < 0 else 0.0
            if wait <= 0:
                break
            self._stop.wait(min(wait, 0.25))
        started = time.thread_time()
        try:
            yield
        finally:
            used = time.thread_time() - started
            with self._lock:
                now = time.monotonic()
                self._credit = max(-MOST_DEBT_SEC, min(
                    MOST_CREDIT_SEC, self._credit + (now - self._at) * self._share) - used)
                self._at = now


class RuleSender:
    """Sends one rule's deliveries, the head first, never past an undelivered one. Its 2xx
    answers are handed to the scanner, whose next transaction records them."""

    def __init__(self, book: AlertBook, rule: AlertRule, stop: threading.Event,
                 answered: threading.Event, pace: Pace, receiver: Receiver | None = None
                 ) -> None:
        self.book = book
        self.pace = pace
        self.rule = rule.name
        self.receiver = receiver or Receiver(rule.receiver)
        self.wake = threading.Event()
        self._stop = stop
        self._answered = answered
        self._awaiting: set[int] = set()
        """Delivered, not yet recorded as delivered: not sent again meanwhile."""
        self._random = random.Random()
        self.thread = threading.Thread(target=self._run, name=f"faultledger-alerts-{rule.name}",
                                       daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                wait = self.round()
            except Exception as error:  # never let a sender die silently
                log.warning("alerts %s: %s: %s", self.rule, type(error).__name__, error)
                wait = ERROR_WAIT_SEC
            if wait is None:
                continue
            self.wake.wait(wait)
            self.wake.clear()

    def round(self) -> float | None:
        """Send what is due; returns how long to wait (None: go on at once)."""
        if self.rule not in self.book.held:
            self._awaiting.clear()
            return POLL_SEC
        with self.pace.work():
            listed = self.book.due(self.rule, BATCH + len(self._awaiting))
        self._awaiting &= {d.id for d in listed}
        room = BATCH - len(self._awaiting)  # never more than a batch answered, unrecorded
        due = [d for d in listed if d.id not in self._awaiting][:room]
        if not due:
            return POLL_SEC  # (a full batch unrecorded: the scanner wakes it once recorded)
        now = time.time_ns()
        if due[0].next_attempt_ns > now:
            self._stop.wait((due[0].next_attempt_ns - now) / NS_PER_SECOND)
            return None
        done: dict[int, int] = {}
        try:
            for delivery in due:
                if self._stop.is_set():
                    break
                with self.pace.work():
                    outcome = self.receiver.send(Alert.from_json(delivery.payload))
                if outcome.delivered:
                    done[delivery.id] = delivery.attempts + 1
                    continue
                if not self._failed(delivery, outcome):
                    return POLL_SEC
                if not outcome.final:
                    return None  # the head waits for its next attempt
        finally:
            if done:
                self.book.sent(self.rule, done)
                self._awaiting.update(done)
                self._answered.set()
        return None if len(due) == BATCH else 0.0

    def _failed(self, delivery: Delivery, outcome: Outcome) -> bool:
        """Record a failed attempt; False when the lease was lost."""
        attempts = delivery.attempts + 1
        wait = alerts.backoff_sec(attempts, self._random.random())
        if outcome.retry_after is not None:
            wait = max(wait, outcome.retry_after)
        now = time.time_ns()
        if not self.book.attempt_failed(self.rule, delivery, outcome.error, outcome.final,
                                        now + int(wait * NS_PER_SECOND), now):
            return False
        if outcome.final:
            log.warning("alerts %s: %s failed for good: %s", self.rule, delivery.key,
                        outcome.error)
        else:
            log.info("alerts %s: %s not delivered (attempt %d): %s; again in %.1f s",
                     self.rule, delivery.key, attempts, outcome.error, wait)
        return True


class AlertDeliverer:
    """The scanner and the senders of one serving process. ``start`` prepares the rules'
    cursors before it returns (so every report the server then answers is scanned), ``stop``
    lets each sender finish its current request, records it, and gives the leases up."""

    def __init__(self, ledger: FaultLedger, rules: Sequence[AlertRule],
                 receivers: Callable[[AlertRule], Receiver] | None = None) -> None:
        self.ledger = ledger
        self.book = AlertBook(ledger, rules)
        self._stop = threading.Event()
        self._wake = threading.Event()
        self.pace = Pace(ledger, self._stop)
        self.senders = {rule.name: RuleSender(self.book, rule, self._stop, self._wake,
                                              self.pace, receivers(rule) if receivers else None)
                        for rule in rules}
        self._subscription: Subscription | None = None
        self._thread = threading.Thread(target=self._scan_loop, name="faultledger-alerts",
                                        daemon=True)

    @classmethod
    def start_for(cls, ledger: FaultLedger, rules: Sequence[AlertRule]
                  ) -> AlertDeliverer | None:
        """A server's deliverer for the config's ``alerts``, started; None without rules."""
        if not rules:
            return None
        deliverer = cls(ledger, rules)
        deliverer.start()
        return deliverer

    @property
    def describe(self) -> str:
        """The server's start line."""
        rules = ", ".join(f"{name} -> {sender.receiver.shown}"
                          for name, sender in self.senders.items())
        return f"alerts: {rules}"

    def start(self) -> None:
        self.book.prepare()
        self.book.renew(time.time_ns())
        # Only a wake-up on the commit path: the scanner reads the log itself.
        self._subscription = self.ledger.subscribe(lambda _notification: self._wake.set())
        self._thread.start()
        for sender in self.senders.values():
            sender.thread.start()

    def stop(self, timeout: float = 15.0) -> None:
        """Each sender finishes the request it is in (at most its answer timeout), then the
        2xx answers not yet recorded are recorded, and the leases are given up."""
        if self._subscription is not None:
            self._subscription.cancel()
        self._stop.set()
        self._wake.set()
        for sender in self.senders.values():
            sender.wake.set()
        deadline = time.monotonic() + timeout
        for thread in (*(s.thread for s in self.senders.values()), self._thread):
            if thread.is_alive():
                thread.join(max(0.0, deadline - time.monotonic()))
        try:
            if self.book.unrecorded():
                self.book.scan(time.time_ns())
            self.book.release()
        except Exception as error:  # the leases then simply expire
            log.warning("alerts: could not record the last deliveries or give the leases "
                        "up: %s", error)
        for sender in self.senders.values():
            sender.receiver.close()

    def _scan_loop(self) -> None:
        renew_at = check_at = 0.0
        while not self._stop.is_set():
            self._wake.clear()
            try:
                now = time.monotonic()
                if now >= renew_at:
                    self.book.renew(time.time_ns())
                    renew_at = now + RENEW_SEC
                more = True
                while more and not self._stop.is_set():
                    with self.pace.work():
                        added, more = self.book.scan(time.time_ns())
                    self._wake_senders({**added, **dict.fromkeys(self.book.recorded, 1)})
                if now >= check_at:
                    if self.book.check_stale(time.time_ns()) + self.book.check_lag(
                            time.time_ns()):
                        self._wake_senders({rule: 1 for rule in self.book.held})
                    check_at = now + CHECK_SEC
            except Exception as error:  # never let the scanner die silently
                log.warning("alerts: scan failed: %s: %s", type(error).__name__, error)
                self._stop.wait(ERROR_WAIT_SEC)
                continue
            self._gap()
            self._wake.wait(min(POLL_SEC, max(0.0, renew_at - time.monotonic())))

    def _gap(self) -> None:
        """The pause between two scans: SCAN_GAP_SEC (BUSY_SCAN_GAP_SEC while ingest is
        busy), cut short to RECORD_GAP_SEC once a sender has answers to record (not while
        busy: then they wait for the next scan)."""
        if self.pace.busy():
            self._stop.wait(BUSY_SCAN_GAP_SEC)
            return
        end = time.monotonic() + SCAN_GAP_SEC
        while not self._stop.wait(RECORD_GAP_SEC) and time.monotonic() < end:
            if self.book.unrecorded():
                break

    def _wake_senders(self, added: dict[str, int]) -> None:
        for rule, count in added.items():
            if count and rule in self.senders:
                self.senders[rule].wake.set()
