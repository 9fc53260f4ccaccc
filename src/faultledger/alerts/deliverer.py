"""The deliverer of a serving process (`serve`, `faultledger http`): one thread scans the log
into the outbox, one thread per rule sends that rule's deliveries in order (docs/alerts.md).

Nothing runs on the report path: the ledger's subscription only sets an Event that wakes the
scanner, which reads the log itself from the rules' cursors. A receiver that is down holds up
only its own rule: its head is tried again with growing waits, and nothing behind it is sent
before it.
"""

from __future__ import annotations

import logging
import random
import threading
import time
from collections.abc import Callable, Sequence

from faultledger.alerts.send import Outcome, Receiver
from faultledger.domain import alerts
from faultledger.domain.alerts import Alert
from faultledger.domain.clock import NS_PER_SECOND
from faultledger.service.alerts import AlertBook
from faultledger.service.config import AlertRule
from faultledger.service.ledger import FaultLedger, Subscription

log = logging.getLogger(__name__)

RENEW_SEC = 5.0
"""How often the leases are renewed (they last 15 s)."""
POLL_SEC = 1.0
"""The scanner looks at the log at least this often (records of other processes)."""
SCAN_GAP_SEC = 0.05
"""Least time between two scans: records arriving meanwhile share the next one."""
CHECK_SEC = 5.0
"""How often stale faults and the fleet's lag are checked."""
ERROR_WAIT_SEC = 1.0
"""After a database error (locked, unavailable): wait, then go on."""
BATCH = 50
"""Deliveries a sender reads at once; their 2xx are recorded together."""
FLUSH_SEC = 0.2
"""A sender records its 2xx answers at least this often while it sends a batch."""


class RuleSender:
    """Sends one rule's deliveries, the head first, never past an undelivered one."""

    def __init__(self, book: AlertBook, rule: AlertRule, stop: threading.Event,
                 receiver: Receiver | None = None) -> None:
        self.book = book
        self.rule = rule.name
        self.receiver = receiver or Receiver(rule.receiver)
        self.wake = threading.Event()
        self._stop = stop
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
            return POLL_SEC
        due = self.book.due(self.rule, BATCH)
        if not due:
            return POLL_SEC
        now = time.time_ns()
        if due[0].next_attempt_ns > now:
            self._stop.wait((due[0].next_attempt_ns - now) / NS_PER_SECOND)
            return None
        done: dict[int, int] = {}
        since = time.monotonic()
        for delivery in due:
            if self._stop.is_set():
                break
            outcome = self.receiver.send(Alert.from_json(delivery.payload))
            if outcome.delivered:
                done[delivery.id] = delivery.attempts + 1
                if time.monotonic() - since >= FLUSH_SEC:
                    if not self._record(done):
                        return POLL_SEC
                    done, since = {}, time.monotonic()
                continue
            if not self._record(done):
                return POLL_SEC
            done = {}
            retried = self._failed(delivery.attempts + 1, outcome)
            now = time.time_ns()
            if not self.book.attempt_failed(self.rule, delivery, outcome.error, outcome.final,
                                            now + int(retried * NS_PER_SECOND), now):
                return POLL_SEC
            if not outcome.final:
                log.info("alerts %s: %s not delivered (attempt %d): %s; again in %.1f s",
                         self.rule, delivery.key, delivery.attempts + 1, outcome.error, retried)
                return None  # the head waits for its next attempt
            log.warning("alerts %s: %s failed for good: %s", self.rule, delivery.key,
                        outcome.error)
        self._record(done)
        return None if len(due) == BATCH else 0.0

    def _failed(self, attempts: int, outcome: Outcome) -> float:
        wait = alerts.backoff_sec(attempts, self._random.random())
        if outcome.retry_after is not None:
            wait = max(wait, outcome.retry_after)
        return wait

    def _record(self, done: dict[int, int]) -> bool:
        if not done:
            return True
        return self.book.delivered(self.rule, done, time.time_ns())


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
        self.senders = {rule.name: RuleSender(self.book, rule, self._stop,
                                              receivers(rule) if receivers else None)
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
        if self._subscription is not None:
            self._subscription.cancel()
        self._stop.set()
        self._wake.set()
        for sender in self.senders.values():
            sender.wake.set()
        deadline = time.monotonic() + timeout
        for thread in (self._thread, *(s.thread for s in self.senders.values())):
            if thread.is_alive():
                thread.join(max(0.0, deadline - time.monotonic()))
        try:
            self.book.release()
        except Exception as error:  # the leases then simply expire
            log.warning("alerts: could not give the leases up: %s", error)
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
                    added, more = self.book.scan(time.time_ns())
                    self._wake_senders(added)
                if now >= check_at:
                    if self.book.check_stale(time.time_ns()) + self.book.check_lag(
                            time.time_ns()):
                        self._wake_senders({rule: 1 for rule in self.book.held})
                    check_at = now + CHECK_SEC
            except Exception as error:  # never let the scanner die silently
                log.warning("alerts: scan failed: %s: %s", type(error).__name__, error)
                self._stop.wait(ERROR_WAIT_SEC)
                continue
            self._stop.wait(SCAN_GAP_SEC)
            self._wake.wait(min(POLL_SEC, max(0.0, renew_at - time.monotonic())))

    def _wake_senders(self, added: dict[str, int]) -> None:
        for rule, count in added.items():
            if count and rule in self.senders:
                self.senders[rule].wake.set()
