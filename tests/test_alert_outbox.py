"""The durable half of alert delivery (service/alerts.py, store/alert_outbox.py) on a real
database of either backend (``--backend postgresql``): the scan from a rule's cursor, its one
transaction with the outbox rows, the leases, the marks of flood and sync_lag, and the whole
deliverer against a receiver on loopback."""

from __future__ import annotations

import random
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import text

from faultledger import FaultLedger, Policy
from faultledger.alerts.deliverer import AlertDeliverer
from faultledger.domain.alerts import Alert
from faultledger.domain.clock import NS_PER_SECOND
from faultledger.errors import FaultLedgerError
from faultledger.service import alerts, fleet
from faultledger.service.alerts import LEASE_NS, AlertBook
from faultledger.service.config import AlertRule
from faultledger.store import alert_outbox
from tests.http.alert_receiver import AlertReceiver, alert_receiver
from tests.test_fleet_central import records_of, robot_log

HOOK = {"type": "webhook", "url": "http://127.0.0.1:9/hook"}


def make_rule(name: str = "hook", on: tuple[str, ...] = ("fault_confirmed",),
              **extra: Any) -> AlertRule:
    return AlertRule.model_validate({"name": name, "on": list(on),
                                     "receiver": extra.pop("receiver", HOOK), **extra})


@pytest.fixture
def ledger(open_ledger: Callable[..., FaultLedger]) -> FaultLedger:
    return open_ledger(Policy())


def outbox(ledger: FaultLedger, rule: str | None = None) -> list[alert_outbox.Delivery]:
    return list(reversed(alerts.deliveries(ledger, rule, limit=1000)))


def cursor_of(ledger: FaultLedger, rule: str) -> int:
    return {r.rule: r.cursor for r in alerts.rule_states(ledger)}[rule]


def refuse(ledger: FaultLedger, backend: str, name: str, event: str, when: str) -> None:
    """A trigger of the database itself that refuses ``event`` (INSERT, UPDATE) on the
    outbox when ``when`` holds of the NEW row: a database error in the middle of a scan."""
    with ledger._db.writing() as conn:
        if backend == "sqlite":
            conn.execute(text(f"CREATE TRIGGER {name} BEFORE {event} ON alert_outbox WHEN "
                              f"{when} BEGIN SELECT RAISE(ABORT, 'refused'); END"))
            return
        conn.execute(text(f"CREATE FUNCTION {name}() RETURNS trigger AS $$ BEGIN IF {when} "
                          "THEN RAISE EXCEPTION 'refused'; END IF; RETURN NEW; END $$ "
                          "LANGUAGE plpgsql"))
        conn.execute(text(f"CREATE TRIGGER {name} BEFORE {event} ON alert_outbox FOR EACH ROW "
                          f"EXECUTE FUNCTION {name}()"))


def allow(ledger: FaultLedger, backend: str, name: str) -> None:
    with ledger._db.writing() as conn:
        conn.execute(text(f"DROP TRIGGER {name}" if backend == "sqlite"
                          else f"DROP TRIGGER {name} ON alert_outbox"))


def scan_all(book: AlertBook) -> dict[str, int]:
    total: dict[str, int] = {}
    more = True
    while more:
        added, more = book.scan(time.time_ns())
        for rule, count in added.items():
            total[rule] = total.get(rule, 0) + count
    return total


def test_a_new_rule_starts_at_the_head_and_scans_each_record_once(ledger: FaultLedger
                                                                   ) -> None:
    assert ledger.report("BEFORE", "FAILED", 3, source_id="/test").accepted
    book = AlertBook(ledger, [make_rule()])
    book.prepare()
    assert cursor_of(ledger, "hook") == ledger.last_seq
    assert book.renew(time.time_ns()) == {"hook"}
    results = [ledger.report(f"AFTER_{i}", "FAILED", 3, source_id="/test") for i in range(3)]
    assert ledger.report("AFTER_0", "PASSED", 3, source_id="/test").accepted  # updated: not in on
    assert scan_all(book) == {"hook": 3}
    assert scan_all(book) == {}
    found = outbox(ledger)
    identity = ledger.identity
    assert identity is not None
    assert [d.key for d in found] == [f"{identity.ledger_id}:{r.seq}:hook" for r in results]
    assert [(d.state, d.attempts, d.event, d.fault_code) for d in found] == [
        ("pending", 0, "fault_confirmed", f"AFTER_{i}") for i in range(3)]
    assert cursor_of(ledger, "hook") == ledger.last_seq
    alert = Alert.from_json(found[0].payload)
    assert (alert.fault_code, alert.status, alert.severity, alert.episode) == (
        "AFTER_0", "CONFIRMED", 3, 1)
    book.prepare()  # a restart: the cursor stays where it is
    assert cursor_of(ledger, "hook") == ledger.last_seq


def test_the_scan_and_the_cursor_are_one_transaction(ledger: FaultLedger,
                                                     backend: str) -> None:
    """A database that refuses one row of the scan keeps neither the rows nor the cursor;
    the next scan (once it accepts them) makes each key once."""
    book = AlertBook(ledger, [make_rule()])
    book.prepare()
    book.renew(time.time_ns())
    start = cursor_of(ledger, "hook")
    for i in range(3):
        assert ledger.report(f"TX_{i}", "FAILED", 3, source_id="/test").accepted
    refuse(ledger, backend, "refuse_tx", "INSERT", "NEW.fault_code = 'TX_2'")
    with pytest.raises(FaultLedgerError):
        book.scan(time.time_ns())
    assert outbox(ledger) == [] and cursor_of(ledger, "hook") == start
    allow(ledger, backend, "refuse_tx")
    assert scan_all(book) == {"hook": 3}
    assert [d.fault_code for d in outbox(ledger)] == ["TX_0", "TX_1", "TX_2"]


def test_one_process_holds_a_rule_until_it_gives_it_up_or_its_lease_expires(
        ledger: FaultLedger) -> None:
    first, second = AlertBook(ledger, [make_rule()]), AlertBook(ledger, [make_rule()])
    first.prepare()
    now = time.time_ns()
    assert first.renew(now) == {"hook"}
    assert second.renew(now) == set()
    assert first.renew(now + 5 * NS_PER_SECOND) == {"hook"}  # renewed
    assert second.renew(now + LEASE_NS) == set()  # not yet expired: renewed at +5 s
    assert second.renew(now + 5 * NS_PER_SECOND + LEASE_NS + 1) == {"hook"}  # expired
    first.held = frozenset({"hook"})
    assert first.renew(now + 5 * NS_PER_SECOND + LEASE_NS + 2) == set()
    second.release()
    assert first.renew(time.time_ns()) == {"hook"}


def test_the_lease_of_a_process_that_ended_is_taken_at_once(ledger: FaultLedger) -> None:
    done = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    dead = f"{alerts.holder_id().split(':')[0]}:{done.stdout.strip()}:00000000"
    dead_book = AlertBook(ledger, [make_rule()], holder=dead)
    dead_book.prepare()
    assert dead_book.renew(time.time_ns()) == {"hook"}
    assert AlertBook(ledger, [make_rule()]).renew(time.time_ns()) == {"hook"}
    other_host = AlertBook(ledger, [make_rule()], holder="elsewhere:1:00000000")
    other_host.renew(time.time_ns() + 2 * LEASE_NS)
    assert AlertBook(ledger, [make_rule()]).renew(time.time_ns() + 2 * LEASE_NS) == set()


def test_a_process_that_lost_its_lease_changes_nothing(ledger: FaultLedger) -> None:
    mine, theirs = AlertBook(ledger, [make_rule()]), AlertBook(ledger, [make_rule()])
    mine.prepare()
    now = time.time_ns()
    mine.renew(now)
    assert ledger.report("LOST_1", "FAILED", 3, source_id="/test").accepted
    assert scan_all(mine) == {"hook": 1}
    [delivery] = outbox(ledger)
    assert theirs.renew(now + LEASE_NS + 1) == {"hook"}  # mine stalled past its lease
    assert ledger.report("LOST_2", "FAILED", 3, source_id="/test").accepted
    mine.sent("hook", {delivery.id: 1})
    assert mine.scan(time.time_ns()) == ({}, False)
    assert mine.held == frozenset()
    assert not mine.attempt_failed("hook", delivery, "x", True, 0, time.time_ns())
    assert [(d.fault_code, d.state) for d in outbox(ledger)] == [("LOST_1", "pending")]
    theirs.sent("hook", {delivery.id: 1})
    assert scan_all(theirs) == {"hook": 1}
    assert [(d.fault_code, d.state) for d in outbox(ledger)] == [
        ("LOST_1", "delivered"), ("LOST_2", "pending")]


def test_filters_and_shelving_decide_at_the_record(ledger: FaultLedger) -> None:
    book = AlertBook(ledger, [make_rule(on=("fault_confirmed", "fault_cleared",
                                            "fault_acknowledged", "fault_updated"),
                                        codes=["HW_*"], min_severity="ERROR")])
    book.prepare()
    book.renew(time.time_ns())
    assert ledger.report("HW_LOW", "FAILED", 1, source_id="/test").accepted  # WARN: too low
    assert ledger.report("ARM", "FAILED", 3, source_id="/test").accepted  # not HW_*
    assert ledger.report("HW_A", "FAILED", 2, source_id="/test").accepted  # confirmed
    assert ledger.report("HW_A", "FAILED", 2, source_id="/test").accepted  # updated
    assert ledger.shelve("HW_A", "1h").success
    assert ledger.report("HW_A", "FAILED", 2, source_id="/test").accepted  # updated, shelved
    assert ledger.clear("HW_A").success  # cleared, shelved
    assert ledger.unshelve("HW_A").success
    assert ledger.report("HW_LOW", "FAILED", 3, source_id="/test").accepted  # CRITICAL now: updated
    assert ledger.acknowledge("HW_LOW").success
    scan_all(book)
    assert [(d.event, d.fault_code) for d in outbox(ledger)] == [
        ("fault_confirmed", "HW_A"), ("fault_updated", "HW_A"),
        ("fault_updated", "HW_LOW"), ("fault_acknowledged", "HW_LOW")]


def test_a_flood_is_counted_across_scans_and_restarts_and_alerted_once(
        ledger: FaultLedger) -> None:
    rule = make_rule("flood", ("flood",))
    book = AlertBook(ledger, [rule])
    book.prepare()
    book.renew(time.time_ns())
    for i in range(6):
        assert ledger.report(f"F_{i}", "FAILED", 3, source_id="/test").accepted
    assert scan_all(book) == {"flood": 0}
    book.release()
    restarted = AlertBook(ledger, [rule])
    restarted.renew(time.time_ns())
    results = [ledger.report(f"F_{i}", "FAILED", 3, source_id="/test") for i in range(6, 14)]
    scan_all(restarted)
    [delivery] = outbox(ledger)
    assert delivery.event == "flood" and delivery.seq == results[4].seq  # the 11th
    alert = Alert.from_json(delivery.payload)
    assert alert.details["confirmations"] == 11 and alert.fault_code == "F_10"
    assert alert.key.endswith(":flood:flood")


def test_a_lagging_robot_log_alerts_once_until_it_catches_up(ledger: FaultLedger,
                                                            tmp_path: Path) -> None:
    rule = make_rule("lag", ("sync_lag",), sync_lag_seconds=60)
    book = AlertBook(ledger, [rule])
    book.prepare()
    robot_id, ledger_id, records = records_of(robot_log(tmp_path / "r.db", "robot-l", 5))
    long_ago = time.time_ns() - 600 * NS_PER_SECOND
    with fleet.Fleet(ledger) as robot_logs:
        robot_logs.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records),
                        now_ns=long_ago)
        now = time.time_ns()
        book.renew(now)
        assert book.check_lag(now) == 1
        assert book.check_lag(now + NS_PER_SECOND) == 0
        [delivery] = outbox(ledger)
        alert = Alert.from_json(delivery.payload)
        assert (alert.event, alert.robot_id, alert.ledger_id, alert.seq) == (
            "sync_lag", robot_id, ledger_id, records[-1].seq)
        assert alert.key == f"{ledger_id}:{records[-1].seq}:lag:sync_lag:{long_ago}"
        robot_logs.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, []))
        assert book.check_lag(time.time_ns()) == 0  # caught up: the mark goes
        later = time.time_ns() + 61 * NS_PER_SECOND
        book.renew(later)
        assert book.check_lag(later) == 1  # lagging again
    assert len(outbox(ledger)) == 2


@pytest.fixture
def receiver() -> Iterator[AlertReceiver]:
    with alert_receiver() as found:
        yield found


def test_the_deliverer_delivers_in_order_and_records_it(ledger: FaultLedger,
                                                        receiver: AlertReceiver) -> None:
    rule = make_rule(receiver={"type": "webhook", "url": receiver.url})
    deliverer = AlertDeliverer(ledger, [rule])
    deliverer.start()
    try:
        results = [ledger.report(f"D_{i:02d}", "FAILED", 3, source_id="/test") for i in range(20)]
        receiver.wait_for(20, timeout=30)
    finally:
        deliverer.stop()
    assert [r.body["seq"] for r in receiver.delivered()] == [r.seq for r in results]
    assert {d.state for d in outbox(ledger)} == {"delivered"}
    assert {r.holder for r in alerts.rule_states(ledger)} == {None}  # given up at stop


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_scans_replay_gives_the_ledgers_own_announcements(
        open_ledger: Callable[..., FaultLedger], seed: int) -> None:
    """Scanned in chunks of any size, from any start, the incremental replay announces what
    FaultLedger.notifications_after does, fault state for fault state, across a policy
    change (healing on, a stricter threshold) and the operator's records."""
    chooser = random.Random(seed)
    codes = [f"P_{i}" for i in range(6)]
    ledger = open_ledger(Policy())
    for phase, policy in enumerate((Policy(), Policy(confirmation_threshold=-2,
                                                      healing_enabled=True,
                                                      healing_threshold=2))):
        if phase:
            ledger.close()
            ledger = open_ledger(policy)
        for _ in range(150):
            code, roll = chooser.choice(codes), chooser.random()
            if roll < 0.7:
                ledger.report(code, chooser.choice(["FAILED", "PASSED"]), chooser.randint(0, 3),
                              source_id=chooser.choice(["/a", "/b"]))
            elif roll < 0.8:
                ledger.clear(code)
            elif roll < 0.9:
                ledger.acknowledge(code)
            else:
                (ledger.shelve(code, "1h") if chooser.random() < 0.5 else ledger.unshelve(code))
    expected = [(n.seq, n.event_type.value, n.fault)
                for n in ledger.notifications_after(0, 100_000)]
    replay = alerts.LogReplay()
    start = chooser.randint(0, 40)
    found: list[tuple[int, str, Any]] = []
    position = start
    while position < ledger.last_seq:
        if chooser.random() < 0.1:
            replay = alerts.LogReplay()  # a restarted process
        changes, position = replay.changes(ledger, position, chooser.randint(1, 60))
        found += [(c.seq, c.event, c.fault) for c in changes]
    assert found == [e for e in expected if e[0] > start]
    assert len(found) > 50


def test_answers_a_failed_scan_could_not_record_are_recorded_by_the_next(
        ledger: FaultLedger, backend: str) -> None:
    book = AlertBook(ledger, [make_rule()])
    book.prepare()
    book.renew(time.time_ns())
    assert ledger.report("ANSWERED", "FAILED", 3, source_id="/test").accepted
    scan_all(book)
    [delivery] = outbox(ledger)
    book.sent("hook", {delivery.id: 1})
    refuse(ledger, backend, "refuse_mark", "UPDATE", "NEW.state = 'delivered'")
    with pytest.raises(FaultLedgerError):
        book.scan(time.time_ns())
    assert book.unrecorded() == 1
    assert [d.state for d in outbox(ledger)] == ["pending"]
    allow(ledger, backend, "refuse_mark")
    book.scan(time.time_ns())
    assert book.unrecorded() == 0
    assert [(d.state, d.attempts) for d in outbox(ledger)] == [("delivered", 1)]
