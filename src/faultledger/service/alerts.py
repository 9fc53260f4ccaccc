"""Alert delivery's durable half (docs/alerts.md): the log → outbox scan, the leases, the
outcomes of sends, and the listing.

The deliverer (``faultledger.alerts``) calls these off the report path, on threads of its
own: the scan reads the log itself (a bounded replay of the faults the new records touch,
like ``FaultLedger.notifications_after``), decides each rule's deliveries with the pure rules
of ``domain.alerts``, and inserts them and moves the rule's cursor in one transaction, so a
crash never skips a delivery and never makes one twice. Each transaction that changes a
rule's rows first checks that this process still holds the rule's lease.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import socket
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import NamedTuple

from sqlalchemy import Connection

from faultledger.domain import alerts
from faultledger.domain.alerts import FLOOD, STALE, SYNC_LAG, Alert
from faultledger.domain.clock import NS_PER_SECOND, from_ns
from faultledger.domain.events import LogRecord
from faultledger.domain.fault import Fault
from faultledger.domain.policy import Policy
from faultledger.domain.projector import Projector
from faultledger.domain.types import FaultStatus
from faultledger.errors import InvalidInputError
from faultledger.service.config import AlertRule
from faultledger.service.fleet import lag_ns
from faultledger.service.ledger import FaultLedger
from faultledger.store import alert_outbox, event_log, fleet_log, projections
from faultledger.store.alert_outbox import ALERTS_LOCK, Delivery, NewDelivery

LEASE_NS = 15 * NS_PER_SECOND
"""How long a lease lasts unless renewed; the deliverer renews it every 5 s."""
SCAN_RECORDS = 2000
"""Records one scan covers at most (one replay, one transaction)."""
FLOOD_HORIZON_NS = 86_400 * NS_PER_SECOND
"""A confirmation counts towards a flood when its window starts at most this long before it
was recorded: a log catching up on old records raises no flood of the past, and a rule keeps
its window counts only this long."""
MAX_LISTED = 1000


class Change(NamedTuple):
    """One announced change of the log, as the scan found it."""

    seq: int
    event: str
    fault: Fault
    occurred_ns: int
    recorded_ns: int


class LogReplay:
    """The faults of the codes it has seen, as of seq ``seq``, and the policy then: each scan
    applies only the records after it (a replay of their codes' histories first, for codes
    it has not seen yet), so a scan costs its own records, not the whole log. The faults come
    out exactly as ``FaultLedger.notifications_after`` has them: faults never affect one
    another, and every policy change is applied in order."""

    def __init__(self) -> None:
        self.seq = -1
        self._faults: dict[str, Fault] = {}
        self._seen: set[str] = set()
        self._policy: Policy | None = None

    def changes(self, ledger: FaultLedger, after: int, most_records: int = SCAN_RECORDS
                ) -> tuple[list[Change], int]:
        """The announcements of the records after seq ``after`` (at most ``most_records``
        of them), and the seq up to which every record was read: one snapshot of the log."""
        with ledger._db.reading() as conn:
            head = event_log.head(conn)[0]
            upto = min(head, after + most_records)
            if upto <= after:
                return [], after
            if after != self.seq:  # the first scan, or a rule whose cursor is elsewhere
                self._faults, self._seen = {}, set()
                self._policy = _replay(event_log.read_of_codes(conn, [], after)).policy
            records = list(event_log.read(conn, after_seq=after, upto_seq=upto))
            codes = {code for code in (r.fault_code for r in records) if code is not None}
            unseen = sorted(codes - self._seen)
            if unseen:
                self._faults.update(_replay(
                    event_log.read_of_codes(conn, unseen, after)).snapshot())
        projector = Projector({c: self._faults[c] for c in codes if c in self._faults},
                              self._policy, after)
        found: list[Change] = []
        for record in records:
            effect = projector.apply_selected(record)
            if effect.notification is not None and effect.fault is not None:
                found.append(Change(record.seq, effect.notification.value, effect.fault,
                                    record.occurred_at_ns, record.recorded_at_ns))
        self._faults.update(projector.snapshot())
        self._seen.update(codes)
        self._policy = projector.policy
        self.seq = upto
        return found, upto


def _replay(records: Iterator[LogRecord]) -> Projector:
    projector = Projector()
    for record in records:
        projector.apply_selected(record)
    return projector


def holder_id() -> str:
    """This process as a lease holder: ``host:pid:nonce``."""
    return f"{socket.gethostname()[:100]}:{os.getpid()}:{secrets.token_hex(4)}"


def ended(holders: Sequence[str | None]) -> set[str]:
    """The holders that are processes of this host which no longer run: their leases are
    taken over at once instead of after they expire (a process killed with -9)."""
    gone: set[str] = set()
    host = socket.gethostname()[:100]
    for holder in holders:
        parts = [] if holder is None else holder.rsplit(":", 2)
        if len(parts) != 3 or parts[0] != host or not parts[1].isdigit():
            continue
        try:
            os.kill(int(parts[1]), 0)
        except ProcessLookupError:
            gone.add(str(holder))
        except (PermissionError, OverflowError):
            continue
    return gone


class AlertBook:
    """One serving process's share of alert delivery: the rules it leases, their cursors,
    and every transaction on their rows. Used by one scanning thread and one sending thread
    per rule; the methods hold no lock of their own (each rule's rows are touched by its
    own sender and by the scanner only through inserts)."""

    def __init__(self, ledger: FaultLedger, rules: Sequence[AlertRule],
                 holder: str | None = None) -> None:
        self.ledger = ledger
        self.rules = {rule.name: rule for rule in rules}
        self.holder = holder or holder_id()
        self.held: frozenset[str] = frozenset()
        self._cursors: dict[str, int] = {}
        self._known: set[str] = set()
        """Keys of derived alerts already in the outbox (stale is found again each check)."""
        self._stretches: dict[str, tuple[Fault, int, int]] = {}
        """code → (the fault as last checked, seq and time of its move into CONFIRMED)."""
        self._replay = LogReplay()
        self._sent: dict[str, dict[int, int]] = {}
        """rule → (delivery id → attempts) answered 2xx, recorded by the next scan."""
        self._sent_lock = threading.Lock()
        self.recorded: frozenset[str] = frozenset()
        """The rules whose answers the last scan recorded (their senders may go on)."""

    @contextlib.contextmanager
    def _writing(self) -> Iterator[Connection]:
        # Not flushed to disk: a power loss may undo the last of these transactions whole
        # (rows, cursor and marks together), which the next scan does again; the log itself
        # stays flushed (docs/alerts.md, "Durability").
        with self.ledger._db.writing(lock_key=ALERTS_LOCK, flush=False) as conn:
            yield conn

    # -- leases and cursors ------------------------------------------------------------------
    def prepare(self) -> None:
        """A cursor at the log's head for each configured rule that has none."""
        with self._writing() as conn:
            alert_outbox.ensure_cursors(conn, self.rules, event_log.head(conn)[0])

    def renew(self, now_ns: int) -> frozenset[str]:
        """Take or renew the lease of every configured rule that is free, expired, held by
        this process or by one that ended; returns the rules this process now holds."""
        with self._writing() as conn:
            found = alert_outbox.cursors(conn)
            gone = ended([c.holder for c in found.values()])
            held = {rule for rule in self.rules if rule in found and alert_outbox.take_lease(
                conn, rule, self.holder, now_ns, now_ns + LEASE_NS, gone)}
        self._cursors = {rule: found[rule].seq for rule in held}
        self.held = frozenset(held)
        return self.held

    def release(self) -> None:
        if not self.held:
            return
        with self._writing() as conn:
            alert_outbox.release(conn, self.held, self.holder)
        self.held = frozenset()

    def _still_held(self, conn: Connection, rules: Sequence[str], now_ns: int) -> list[str]:
        """The rules whose lease and cursor are as this process left them."""
        current = alert_outbox.cursors(conn)
        kept = [rule for rule in rules if rule in current
                and current[rule].holder == self.holder
                and current[rule].lease_until_ns > now_ns
                and current[rule].seq == self._cursors.get(rule)]
        lost = set(rules) - set(kept)
        if lost:
            self.held = self.held - lost
        return kept

    # -- the scan ----------------------------------------------------------------------------
    def scan(self, now_ns: int) -> tuple[dict[str, int], bool]:
        """Turn the records after the held rules' cursors into deliveries, and record the
        deliveries answered 2xx since the last scan, in one transaction: (new deliveries per
        rule, whether records remain beyond this scan)."""
        rules = sorted(self.held)
        identity = self.ledger.identity
        self.recorded = frozenset()
        with self._sent_lock:
            sent, self._sent = self._sent, {}
        changes: list[Change] = []
        after = through = 0
        if rules and identity is not None:
            after = min(self._cursors[rule] for rule in rules)
            changes, through = self._replay.changes(self.ledger, after)
        if through <= after and not sent:
            return {}, False
        added: dict[str, int] = {}
        try:
            with self._writing() as conn:
                kept = self._still_held(conn, sorted(set(rules) | set(sent)), now_ns)
                for name in kept:
                    if name in sent:
                        alert_outbox.mark_delivered(conn, sorted(sent[name]), sent[name],
                                                    now_ns)
                    if through <= after or name not in self.rules or identity is None:
                        continue
                    rows = self._rows(conn, self.rules[name], changes, identity.ledger_id,
                                      identity.robot_id)
                    added[name] = alert_outbox.add(conn, rows, now_ns)
                    if through > self._cursors[name]:
                        alert_outbox.move_cursor(conn, name, through)
        except BaseException:
            for name, done in sent.items():  # recorded by the next scan instead
                self.sent(name, done)
            raise
        for name in added:
            self._cursors[name] = max(self._cursors[name], through)
        self.recorded = frozenset(name for name in kept if name in sent)
        return added, through > after and through < self.ledger.last_seq

    def sent(self, rule: str, done: dict[int, int]) -> None:
        """Deliveries (id → attempts) the receiver answered 2xx: recorded as delivered by
        the next scan's transaction (one transaction for a scan and every sender's answers
        since the last, instead of one each)."""
        with self._sent_lock:
            self._sent.setdefault(rule, {}).update(done)

    def unrecorded(self) -> int:
        with self._sent_lock:
            return sum(len(done) for done in self._sent.values())

    def _rows(self, conn: Connection, rule: AlertRule, changes: list[Change], ledger_id: str,
              robot_id: str) -> list[NewDelivery]:
        """A rule's deliveries of the changes after its cursor, in seq order; a flood
        follows the confirmation that made it."""
        cursor = self._cursors[rule.name]
        codes = tuple(rule.codes)
        flood = FLOOD in rule.on
        windows = alert_outbox.marks(conn, rule.name, "flood:") if flood else {}
        newest = 0
        rows: list[NewDelivery] = []
        for change in changes:
            if change.seq <= cursor:
                continue
            fault = change.fault
            selected = alerts.selects(codes, rule.min_severity, fault.fault_code,
                                      fault.severity)
            if (selected and change.event in rule.on
                    and alerts.alerts_for(fault, change.recorded_ns)):
                alert = alerts.fault_alert(change.event, rule.name, change.seq, ledger_id,
                                           robot_id, change.occurred_ns, fault)
                rows.append(_row(rule.name, alert, change.recorded_ns))
            if flood and selected and change.event == alerts.CONFIRMED:
                newest = max(newest, change.recorded_ns)
                window = alerts.flood_window(change.occurred_ns)
                if window < change.recorded_ns - FLOOD_HORIZON_NS:
                    continue
                mark = f"flood:{window}"
                windows[mark] = windows.get(mark, 0) + 1
                if windows[mark] == alerts.FLOOD_MORE_THAN + 1:
                    rows.append(_row(rule.name, _flood(rule.name, change, window,
                                                      windows[mark], ledger_id, robot_id),
                                     change.recorded_ns))
        if flood and newest:
            horizon = newest - FLOOD_HORIZON_NS - alerts.FLOOD_WINDOW_NS
            old = [m for m in windows if int(m.split(":", 1)[1]) < horizon]
            alert_outbox.drop_marks(conn, rule.name, old)
            alert_outbox.set_marks(conn, rule.name, {m: v for m, v in windows.items()
                                                     if m not in old})
        return rows

    # -- conditions of time ------------------------------------------------------------------
    def check_stale(self, now_ns: int) -> int:
        """Deliveries for faults CONFIRMED for 24 h or more (docs/statistics.md), once per
        move into CONFIRMED, anchored at the seq of that move; a fault is considered only
        once a rule's scan has passed that seq (its confirmation is delivered first)."""
        rules = [self.rules[name] for name in sorted(self.held) if STALE in self.rules[name].on]
        identity = self.ledger.identity
        if not rules or identity is None:
            return 0
        due = [f for f in self.ledger.list_faults([FaultStatus.CONFIRMED.value])
               if f.confirmed_ns and now_ns - f.confirmed_ns >= alerts.STALE_AFTER_NS]
        rows: list[NewDelivery] = []
        for fault in due:
            stretch = self._stretch(fault)
            if stretch is None or now_ns - stretch[1] < alerts.STALE_AFTER_NS:
                continue
            seq, since_ns = stretch
            for rule in rules:
                if (seq > self._cursors[rule.name] or not alerts.alerts_for(fault, now_ns)
                        or not alerts.selects(tuple(rule.codes), rule.min_severity,
                                              fault.fault_code, fault.severity)):
                    continue
                alert = _stale(rule.name, fault, seq, since_ns, identity.ledger_id,
                               identity.robot_id)
                if alert.key not in self._known:
                    rows.append(_row(rule.name, alert, since_ns + alerts.STALE_AFTER_NS))
        return self._add_derived(rows, now_ns)

    def _stretch(self, fault: Fault) -> tuple[int, int] | None:
        """(seq, time) of the fault's move into CONFIRMED, from the saved transitions; None
        while they do not show it yet (saved behind the log, docs/architecture.md)."""
        cached = self._stretches.get(fault.fault_code)
        if cached is not None and cached[0] == fault:
            return cached[1], cached[2]
        with self.ledger._db.reading() as conn:
            last = projections.last_transition(conn, fault.fault_code)
        if last is None or last.to_status is not FaultStatus.CONFIRMED:
            return None
        self._stretches[fault.fault_code] = (fault, last.seq, last.at_ns)
        return last.seq, last.at_ns

    def check_lag(self, now_ns: int) -> int:
        """On a fleet central: a delivery when a robot log's lag passes a rule's
        ``sync_lag_seconds``, once until it is back under it (a mark per rule and log)."""
        rules = [self.rules[name] for name in sorted(self.held)
                 if SYNC_LAG in self.rules[name].on]
        if not rules:
            return 0
        with self.ledger._db.reading() as conn:
            chains = fleet_log.chains(conn)
        if not chains:
            return 0
        added = 0
        with self._writing() as conn:
            for name in self._still_held(conn, [r.name for r in rules], now_ns):
                rule = self.rules[name]
                lagging = alert_outbox.marks(conn, name, "lag:")
                threshold_ns = int(rule.sync_lag_seconds * NS_PER_SECOND)
                rows, marks, ended_marks = [], {}, []
                for chain in chains:
                    mark = f"lag:{chain.ledger_id}"
                    over = lag_ns(chain, now_ns) > threshold_ns
                    if over and mark not in lagging:
                        alert = _sync_lag(name, chain, rule.sync_lag_seconds)
                        rows.append(_row(name, alert, alert.occurred_ns))
                        marks[mark] = chain.last_seq
                    elif not over and mark in lagging:
                        ended_marks.append(mark)
                added += alert_outbox.add(conn, rows, now_ns)
                alert_outbox.set_marks(conn, name, marks)
                alert_outbox.drop_marks(conn, name, ended_marks)
        return added

    def _add_derived(self, rows: list[NewDelivery], now_ns: int) -> int:
        if not rows:
            return 0
        with self._writing() as conn:
            kept = set(self._still_held(conn, sorted({r.rule for r in rows}), now_ns))
            rows = [r for r in rows if r.rule in kept]
            added = alert_outbox.add(conn, rows, now_ns)
        self._known.update(r.key for r in rows)
        return added

    # -- sending -----------------------------------------------------------------------------
    def due(self, rule: str, limit: int = 50) -> list[Delivery]:
        """The rule's undelivered deliveries, the head first."""
        with self.ledger._db.reading() as conn:
            return alert_outbox.undelivered(conn, rule, limit)

    def attempt_failed(self, rule: str, delivery: Delivery, error: str, final: bool,
                       next_attempt_ns: int, now_ns: int) -> bool:
        """Record a failed attempt: ``failed`` (final) or ``retrying`` until
        ``next_attempt_ns``; False when the lease was lost."""
        with self._writing() as conn:
            if not alert_outbox.holds(conn, rule, self.holder, now_ns):
                return False
            alert_outbox.mark_attempt(
                conn, delivery.id, alert_outbox.FAILED if final else alert_outbox.RETRYING,
                delivery.attempts + 1, error[:2000], next_attempt_ns)
        return True


def _row(rule: str, alert: Alert, due_ns: int) -> NewDelivery:
    return NewDelivery(rule, alert.key, alert.seq, alert.event, alert.fault_code, due_ns,
                       alert.to_json())


def _flood(rule: str, change: Change, window: int, count: int, ledger_id: str,
           robot_id: str) -> Alert:
    fault = change.fault
    return Alert(FLOOD, alerts.key(ledger_id, change.seq, rule, FLOOD), change.seq, ledger_id,
                 robot_id, change.occurred_ns, f"{ledger_id}:flood:{window}", fault.fault_code,
                 fault.severity, fault.status.value, fault.episode, fault.description,
                 {"window_start": from_ns(window).isoformat(), "window_start_ns": window,
                  "window_end": from_ns(window + alerts.FLOOD_WINDOW_NS).isoformat(),
                  "confirmations": count, "more_than": alerts.FLOOD_MORE_THAN})


def _stale(rule: str, fault: Fault, seq: int, since_ns: int, ledger_id: str,
           robot_id: str) -> Alert:
    return Alert(STALE, alerts.key(ledger_id, seq, rule, STALE), seq, ledger_id, robot_id,
                 since_ns, f"{alerts.episode_incident(ledger_id, fault)}:stale",
                 fault.fault_code, fault.severity, fault.status.value, fault.episode,
                 fault.description,
                 {"confirmed_since": from_ns(since_ns).isoformat(),
                  "stale_since": from_ns(since_ns + alerts.STALE_AFTER_NS).isoformat()})


def _sync_lag(rule: str, chain: fleet_log.Chain, threshold_sec: float) -> Alert:
    since_ns = chain.complete_until_ns or chain.first_contact_ns
    crossed_ns = since_ns + int(threshold_sec * NS_PER_SECOND)
    return Alert(SYNC_LAG, alerts.key(chain.ledger_id, chain.last_seq, rule, SYNC_LAG,
                                      f":{since_ns}"),
                 chain.last_seq, chain.ledger_id, chain.robot_id, crossed_ns,
                 f"{chain.ledger_id}:sync_lag:{since_ns}",
                 details={"complete_until": from_ns(since_ns).isoformat(),
                          "threshold_seconds": threshold_sec, "last_seq": chain.last_seq})


# -- the listing -------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class RuleState:
    """One rule as the database holds it: its cursor, lease and deliveries per state."""

    rule: str
    cursor: int
    holder: str | None
    lease_until_ns: int
    counts: dict[str, int]
    oldest_undelivered_ns: int | None


def rule_states(ledger: FaultLedger) -> list[RuleState]:
    with ledger._db.reading() as conn:
        found = alert_outbox.cursors(conn)
        counts = alert_outbox.counts(conn)
        oldest = alert_outbox.oldest_undelivered(conn)
    names = sorted(set(found) | {rule for rule, _ in counts})
    return [RuleState(name, found[name].seq if name in found else 0,
                      found[name].holder if name in found else None,
                      found[name].lease_until_ns if name in found else 0,
                      {state: counts.get((name, state), 0) for state in alert_outbox.STATES},
                      oldest.get(name)) for name in names]


def deliveries(ledger: FaultLedger, rule: str | None = None, states: Sequence[str] = (),
               limit: int = 100) -> list[Delivery]:
    """Deliveries, newest first; an unknown state or a limit out of 1..1000 is refused."""
    unknown = [s for s in states if s not in alert_outbox.STATES]
    if unknown:
        raise InvalidInputError(f"unknown state {unknown[0]!r}; the states are "
                                f"{', '.join(alert_outbox.STATES)}")
    if isinstance(limit, bool) or not isinstance(limit, int) or not 1 <= limit <= MAX_LISTED:
        raise InvalidInputError(f"limit must be 1 to {MAX_LISTED}, got {limit!r}")
    if rule is not None and alerts.RULE_NAME.fullmatch(rule) is None:
        raise InvalidInputError(f"rule must be {alerts.RULE_NAME_RULE}; got {rule!r}")
    with ledger._db.reading() as conn:
        return alert_outbox.listing(conn, rule, states, limit)


def lag_ns_of(delivery: Delivery, now_ns: int) -> int:
    """Delivered: how long after its record it was delivered; otherwise how long it has
    been due."""
    end = delivery.delivered_ns if delivery.delivered_ns is not None else now_ns
    return max(0, end - delivery.record_ns)


def _at(ns: int | None) -> str | None:
    return None if not ns else from_ns(ns).isoformat(timespec="milliseconds")


def delivery_dict(delivery: Delivery, now_ns: int) -> dict[str, object]:
    """One delivery as `faultledger alerts --json` and GET /api/v1/alerts give it."""
    undelivered = delivery.state in alert_outbox.UNDELIVERED
    return {
        "rule": delivery.rule, "key": delivery.key, "seq": delivery.seq,
        "event": delivery.event, "fault_code": delivery.fault_code, "state": delivery.state,
        "attempts": delivery.attempts, "last_error": delivery.last_error,
        "due_at": _at(delivery.record_ns), "created_at": _at(delivery.created_ns),
        "delivered_at": _at(delivery.delivered_ns),
        "next_attempt_at": _at(delivery.next_attempt_ns) if undelivered else None,
        "lag_seconds": round(lag_ns_of(delivery, now_ns) / NS_PER_SECOND, 3),
    }


def rule_dict(state: RuleState, now_ns: int) -> dict[str, object]:
    held = state.holder is not None and state.lease_until_ns > now_ns
    return {
        "rule": state.rule, "cursor": state.cursor, "holder": state.holder if held else None,
        "lease_until": _at(state.lease_until_ns) if held else None,
        "deliveries": state.counts,
        "oldest_undelivered_seconds": None if state.oldest_undelivered_ns is None
        else round(max(0, now_ns - state.oldest_undelivered_ns) / NS_PER_SECOND, 3),
    }
