"""The alert outbox, the rules' cursors and leases, and their marks (docs/alerts.md).

Every function runs in the caller's transaction: the service moves a rule's cursor in the
transaction that inserts the rows its scan found, and checks the lease in each transaction
that changes a rule's rows, so a process that lost the lease changes nothing.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Connection, delete, func, insert, select, update
from sqlalchemy.dialects import postgresql, sqlite

from faultledger.store.schema import alert_cursors, alert_marks, alert_outbox

ALERTS_LOCK = 0x66_6C_65_64_61_6C_72  # "fledalr"
"""PostgreSQL: the lock alert transactions take instead of the log's write lock, so they never
wait for (or hold up) the writer; on SQLite every write transaction takes the one lock."""
PENDING, RETRYING, DELIVERED, FAILED = "pending", "retrying", "delivered", "failed"
STATES = (PENDING, RETRYING, DELIVERED, FAILED)
UNDELIVERED = (PENDING, RETRYING)
"""States a rule's sender still works on, oldest first; ``failed`` and ``delivered`` are
final."""


@dataclass(frozen=True, slots=True)
class Cursor:
    rule: str
    seq: int
    holder: str | None
    lease_until_ns: int


@dataclass(frozen=True, slots=True)
class NewDelivery:
    rule: str
    key: str
    seq: int
    event: str
    fault_code: str | None
    record_ns: int
    payload: str


@dataclass(frozen=True, slots=True)
class Delivery:
    id: int
    rule: str
    key: str
    seq: int
    event: str
    fault_code: str | None
    record_ns: int
    payload: str
    state: str
    attempts: int
    last_error: str | None
    next_attempt_ns: int
    created_ns: int
    delivered_ns: int | None


def _delivery(row: Any) -> Delivery:
    return Delivery(*(row[i] for i in range(14)))


# -- cursors and leases ----------------------------------------------------------------------
def ensure_cursors(conn: Connection, rules: Iterable[str], head_seq: int) -> None:
    """A cursor at ``head_seq`` for each rule that has none: a new rule alerts from now on."""
    known = {row[0] for row in conn.execute(select(alert_cursors.c.rule))}
    missing = [rule for rule in rules if rule not in known]
    if missing:
        conn.execute(insert(alert_cursors), [
            {"rule": rule, "seq": head_seq, "holder": None, "lease_until_ns": 0}
            for rule in missing])


def cursors(conn: Connection) -> dict[str, Cursor]:
    return {row[0]: Cursor(*row) for row in conn.execute(
        select(alert_cursors).order_by(alert_cursors.c.rule))}


def take_lease(conn: Connection, rule: str, holder: str, now_ns: int, until_ns: int,
               gone: set[str]) -> bool:
    """Hold ``rule`` until ``until_ns``: renewed when ``holder`` holds it, taken when it is
    free, expired, or held by a holder in ``gone`` (a process known to have ended)."""
    row = conn.execute(select(alert_cursors.c.holder, alert_cursors.c.lease_until_ns)
                       .where(alert_cursors.c.rule == rule)).first()
    if row is None:
        return False
    current, until = row
    if current not in (None, holder) and until > now_ns and current not in gone:
        return False
    conn.execute(update(alert_cursors).where(alert_cursors.c.rule == rule)
                 .values(holder=holder, lease_until_ns=until_ns))
    return True


def holds(conn: Connection, rule: str, holder: str, now_ns: int) -> bool:
    row = conn.execute(select(alert_cursors.c.holder, alert_cursors.c.lease_until_ns)
                       .where(alert_cursors.c.rule == rule)).first()
    return row is not None and row[0] == holder and row[1] > now_ns


def release(conn: Connection, rules: Iterable[str], holder: str) -> None:
    """Give the leases up at once (a clean stop): another process may take them now."""
    conn.execute(update(alert_cursors).where(alert_cursors.c.rule.in_(list(rules)),
                                             alert_cursors.c.holder == holder)
                 .values(holder=None, lease_until_ns=0))


def move_cursor(conn: Connection, rule: str, seq: int) -> None:
    conn.execute(update(alert_cursors).where(alert_cursors.c.rule == rule).values(seq=seq))


# -- the outbox ------------------------------------------------------------------------------
def add(conn: Connection, rows: Sequence[NewDelivery], now_ns: int) -> int:
    """Insert deliveries as pending; a key already there is left as it is (a derived event
    found again). Returns how many were new."""
    known = known_keys(conn, [r.key for r in rows])
    fresh = [r for r in rows if r.key not in known]
    if not fresh:
        return 0
    module: Any = postgresql if conn.dialect.name == "postgresql" else sqlite
    statement = module.insert(alert_outbox).on_conflict_do_nothing(index_elements=["key"])
    conn.execute(statement, [{
        "rule": r.rule, "key": r.key, "seq": r.seq, "event": r.event,
        "fault_code": r.fault_code, "record_ns": r.record_ns, "payload": r.payload,
        "state": PENDING, "attempts": 0, "last_error": None, "next_attempt_ns": 0,
        "created_ns": now_ns, "delivered_ns": None} for r in fresh])
    return len(fresh)


def known_keys(conn: Connection, keys: Sequence[str]) -> set[str]:
    found: set[str] = set()
    for start in range(0, len(keys), 500):  # bounded IN lists
        found.update(conn.execute(select(alert_outbox.c.key).where(
            alert_outbox.c.key.in_(list(keys[start:start + 500])))).scalars())
    return found


def undelivered(conn: Connection, rule: str, limit: int) -> list[Delivery]:
    """A rule's pending and retrying deliveries, oldest first (the head first)."""
    query = (select(alert_outbox).where(alert_outbox.c.rule == rule,
                                        alert_outbox.c.state.in_(UNDELIVERED))
             .order_by(alert_outbox.c.id).limit(limit))
    return [_delivery(row) for row in conn.execute(query)]


def mark_delivered(conn: Connection, ids: Sequence[int], attempts: dict[int, int],
                   now_ns: int) -> None:
    for delivery_id in ids:
        conn.execute(update(alert_outbox).where(alert_outbox.c.id == delivery_id).values(
            state=DELIVERED, attempts=attempts[delivery_id], delivered_ns=now_ns))


def mark_attempt(conn: Connection, delivery_id: int, state: str, attempts: int, error: str,
                 next_attempt_ns: int) -> None:
    """A failed attempt: ``retrying`` (tried again at ``next_attempt_ns``) or ``failed``."""
    conn.execute(update(alert_outbox).where(alert_outbox.c.id == delivery_id).values(
        state=state, attempts=attempts, last_error=error, next_attempt_ns=next_attempt_ns))


def listing(conn: Connection, rule: str | None = None, states: Sequence[str] = (),
            limit: int = 100) -> list[Delivery]:
    """Deliveries, newest first."""
    query = select(alert_outbox).order_by(alert_outbox.c.id.desc()).limit(limit)
    if rule is not None:
        query = query.where(alert_outbox.c.rule == rule)
    if states:
        query = query.where(alert_outbox.c.state.in_(list(states)))
    return [_delivery(row) for row in conn.execute(query)]


def counts(conn: Connection) -> dict[tuple[str, str], int]:
    """(rule, state) → deliveries."""
    query = (select(alert_outbox.c.rule, alert_outbox.c.state, func.count())
             .group_by(alert_outbox.c.rule, alert_outbox.c.state))
    return {(row[0], row[1]): int(row[2]) for row in conn.execute(query)}


def oldest_undelivered(conn: Connection) -> dict[str, int]:
    """rule → the recording time of its oldest undelivered delivery's record."""
    query = (select(alert_outbox.c.rule, func.min(alert_outbox.c.record_ns))
             .where(alert_outbox.c.state.in_(UNDELIVERED)).group_by(alert_outbox.c.rule))
    return {row[0]: int(row[1]) for row in conn.execute(query)}


# -- marks -----------------------------------------------------------------------------------
def marks(conn: Connection, rule: str, prefix: str) -> dict[str, int]:
    query = select(alert_marks.c.mark, alert_marks.c.value).where(
        alert_marks.c.rule == rule, alert_marks.c.mark.startswith(prefix, autoescape=True))
    return {row[0]: int(row[1]) for row in conn.execute(query)}


def set_marks(conn: Connection, rule: str, values: dict[str, int]) -> None:
    """Set (insert or replace) marks of a rule."""
    if not values:
        return
    conn.execute(delete(alert_marks).where(alert_marks.c.rule == rule,
                                           alert_marks.c.mark.in_(list(values))))
    conn.execute(insert(alert_marks), [{"rule": rule, "mark": mark, "value": value}
                                       for mark, value in values.items()])


def drop_marks(conn: Connection, rule: str, names: Iterable[str]) -> None:
    listed = list(names)
    if listed:
        conn.execute(delete(alert_marks).where(alert_marks.c.rule == rule,
                                               alert_marks.c.mark.in_(listed)))
