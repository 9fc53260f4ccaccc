"""SPEC §3: a re-sent record (same event_id) is stored once; many threads report at once into
one gap-free, verifiable log; subscribers hear every change in log order."""

from __future__ import annotations

import threading
import uuid
from collections.abc import Callable
from pathlib import Path

from faultledger import FaultLedger, Notification, Policy, ReportRequest, ReportResult

THREADS = 8
PER_THREAD = 200


def url(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'faults.db'}"


def run_threads(count: int, target: Callable[[int], None]) -> None:
    """Start ``count`` threads together (barrier) and join them; re-raise the first error."""
    barrier = threading.Barrier(count)
    errors: list[BaseException] = []

    def body(n: int) -> None:
        try:
            barrier.wait()
            target(n)
        except BaseException as error:  # surfaced in the test thread below
            errors.append(error)

    threads = [threading.Thread(target=body, args=(n,), daemon=True) for n in range(count)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=120)
    assert not any(t.is_alive() for t in threads), "reporting threads hung"
    if errors:
        raise errors[0]


def stored_ids(ledger: FaultLedger, event_id: str) -> list[int]:
    return [r.seq for r in ledger.history() if r.event_id == event_id]


# -- idempotency ---------------------------------------------------------------------------------
def test_same_event_id_twice_is_stored_once(tmp_path: Path) -> None:
    event_id = str(uuid.uuid4())
    with FaultLedger.open(url(tmp_path)) as ledger:
        first = ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", event_id=event_id)
        length = ledger.last_seq
        second = ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", event_id=event_id)
        assert first.accepted and not first.duplicate and first.seq is not None
        assert second.accepted and second.duplicate, second.message
        assert second.event_id == event_id
        assert ledger.last_seq == length
        assert stored_ids(ledger, event_id) == [first.seq]


def spellings(event_id: uuid.UUID) -> list[str]:
    """What ``uuid.UUID`` reads as this id: upper case, braces, URN, no hyphens."""
    text = str(event_id)
    return [text.upper(), "{" + text + "}", f"urn:uuid:{text}", event_id.hex]


def test_every_spelling_of_an_event_id_is_one_report(tmp_path: Path) -> None:
    """Issue 18: the id is stored in its canonical form (lowercase, hyphenated) and compared
    in it, one by one and within one batch alike."""
    alone, batched = uuid.uuid4(), uuid.uuid4()
    with FaultLedger.open(url(tmp_path)) as ledger:
        one_by_one = [ledger.report("SPELLED", "FAILED", 1, "", "/x", event_id=spelling)
                      for spelling in spellings(alone)]
        in_a_batch = ledger.report_many([ReportRequest("SPELLED", "FAILED", 1, "", "/x",
                                                       event_id=spelling)
                                         for spelling in spellings(batched)])
        for results, event_id in ((one_by_one, alone), (in_a_batch, batched)):
            assert [r.accepted for r in results] == [True] * 4
            assert [r.duplicate for r in results] == [False, True, True, True]
            assert {r.event_id for r in results} == {str(event_id)}
            assert len(stored_ids(ledger, str(event_id))) == 1
        assert len(ledger.history(kinds=["fault_reported"])) == 2


def test_duplicate_report_does_not_change_the_fault(tmp_path: Path) -> None:
    event_id = str(uuid.uuid4())
    policy = Policy(confirmation_threshold=-3)
    with FaultLedger.open(url(tmp_path), policy=policy, background=False) as ledger:
        ledger.report("MOTOR_OVERHEAT", "FAILED", 1, "first", "/motor", event_id=event_id)
        before = ledger.get_fault("MOTOR_OVERHEAT")
        ledger.report("MOTOR_OVERHEAT", "FAILED", 3, "resent", "/other", event_id=event_id)
        assert ledger.get_fault("MOTOR_OVERHEAT") == before


def test_duplicate_report_is_not_announced(tmp_path: Path) -> None:
    event_id = str(uuid.uuid4())
    with FaultLedger.open(url(tmp_path)) as ledger:
        received: list[Notification] = []
        ledger.subscribe(received.append)
        ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", event_id=event_id)
        assert len(received) == 1  # fault_confirmed
        ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", event_id=event_id)
        assert len(received) == 1


def test_same_event_id_from_two_threads_at_once_is_stored_once(tmp_path: Path) -> None:
    ids = [str(uuid.uuid4()) for _ in range(50)]
    answers: dict[int, list[ReportResult]] = {0: [], 1: []}
    with FaultLedger.open(url(tmp_path)) as ledger:

        def resend(n: int) -> None:
            for i, event_id in enumerate(ids):
                answers[n].append(ledger.report(f"CODE_{i % 5}", "FAILED", 1, "", f"/r{n}",
                                                event_id=event_id))

        run_threads(2, resend)
        history = ledger.history()
    for a, b in zip(answers[0], answers[1], strict=True):
        assert a.accepted and b.accepted, (a.message, b.message)
        assert sorted([a.duplicate, b.duplicate]) == [False, True], (a, b)
    stored = [r.event_id for r in history if r.event_id in set(ids)]
    assert sorted(stored) == sorted(ids)


def test_same_event_id_after_close_and_reopen_is_stored_once(tmp_path: Path) -> None:
    event_id = str(uuid.uuid4())
    with FaultLedger.open(url(tmp_path)) as ledger:
        first = ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", event_id=event_id)
        length = ledger.last_seq
    with FaultLedger.open(url(tmp_path)) as ledger:
        second = ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", event_id=event_id)
        assert second.accepted and second.duplicate, second.message
        assert ledger.last_seq == length
        assert stored_ids(ledger, event_id) == [first.seq]


def test_same_event_id_across_two_open_ledgers_is_stored_once(tmp_path: Path) -> None:
    """Two processes' ledgers on one file (e.g. a bridge re-sending to a restarted node)."""
    event_id = str(uuid.uuid4())
    with FaultLedger.open(url(tmp_path)) as one, FaultLedger.open(url(tmp_path)) as two:
        first = one.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", event_id=event_id)
        second = two.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", event_id=event_id)
        assert first.accepted and not first.duplicate
        assert second.accepted and second.duplicate, second.message
        assert stored_ids(two, event_id) == [first.seq]


def test_event_id_that_is_not_a_uuid_is_rejected(tmp_path: Path) -> None:
    with FaultLedger.open(url(tmp_path)) as ledger:
        result = ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor", event_id="msg-42")
        assert not result.accepted
        assert "UUID" in result.message
        assert ledger.history() == []


# -- concurrency ---------------------------------------------------------------------------------
def report_concurrently(ledger: FaultLedger) -> dict[int, list[ReportResult]]:
    """THREADS x PER_THREAD FAILED reports over 40 codes (every one is recorded)."""
    results: dict[int, list[ReportResult]] = {n: [] for n in range(THREADS)}

    def reporter(n: int) -> None:
        for i in range(PER_THREAD):
            results[n].append(ledger.report(f"CODE_{(n * 7 + i) % 40:02d}", "FAILED",
                                            i % 4, f"t{n} i{i}", f"/robot/{n}"))

    run_threads(THREADS, reporter)
    return results


def test_eight_threads_reporting_are_all_acknowledged_in_a_gap_free_log(tmp_path: Path) -> None:
    with FaultLedger.open(url(tmp_path)) as ledger:
        results = report_concurrently(ledger)
        history = ledger.history()
        last = ledger.last_seq
    answers = [r for per in results.values() for r in per]
    assert len(answers) == THREADS * PER_THREAD
    assert all(r.accepted and r.seq is not None for r in answers), [
        r.message for r in answers if not r.accepted][:3]
    assert [r.seq for r in history] == list(range(1, last + 1))
    by_seq: dict[int | None, str] = {r.seq: r.event_id for r in history}
    assert all(by_seq[r.seq] == r.event_id for r in answers)
    assert len({r.seq for r in answers}) == len(answers)
    # besides the reports only the log's identity and the policy (before the first report)
    assert [r.kind for r in history[:2]] == ["ledger_identified", "policy_changed"]
    assert [r.kind for r in history].count("fault_reported") == len(answers)
    assert last == len(answers) + 2


def test_each_thread_sees_its_own_reports_in_order(tmp_path: Path) -> None:
    with FaultLedger.open(url(tmp_path)) as ledger:
        results = report_concurrently(ledger)
    for per in results.values():
        seqs = [r.seq or 0 for r in per]
        assert seqs == sorted(seqs)


def test_log_written_by_eight_threads_verifies(tmp_path: Path) -> None:
    with FaultLedger.open(url(tmp_path)) as ledger:
        report_concurrently(ledger)
        report = ledger.verify()
        assert report.ok, report.problems
        assert report.records == THREADS * PER_THREAD + 2  # and the identity, the policy
        assert ledger.all_faults() == ledger.state_at(ledger.last_seq)


def test_single_reports_and_batches_from_many_threads_are_all_answered(tmp_path: Path) -> None:
    """Callers answered by one commit are woken one by the other: none may be left waiting,
    whether it sent one report or a batch (whose reports may span several commits)."""
    answered: dict[int, list[ReportResult]] = {}

    with FaultLedger.open(url(tmp_path), background=False) as ledger:

        def worker(n: int) -> None:
            mine: list[ReportResult] = []
            for i in range(60):
                if n % 2:
                    mine.append(ledger.report(f"CODE_{n}_{i % 7}", "FAILED", 1, "", f"/r/{n}"))
                else:
                    mine.extend(ledger.report_many([
                        ReportRequest(f"CODE_{n}_{(i + k) % 7}", "FAILED", 1, "", f"/r/{n}")
                        for k in range(1 + i % 9)]))
            answered[n] = mine

        run_threads(THREADS, worker)
        last = ledger.last_seq
        history = ledger.history()
    sent = sum(60 if n % 2 else sum(1 + i % 9 for i in range(60)) for n in range(THREADS))
    answers = [r for per in answered.values() for r in per]
    assert len(answers) == sent
    assert all(r.accepted for r in answers)
    assert sorted(r.seq or 0 for r in answers) == list(range(3, last + 1))
    assert [r.seq for r in history] == list(range(1, last + 1))


def test_concurrent_reports_and_clears_keep_state_equal_to_replay(tmp_path: Path) -> None:
    policy = Policy(confirmation_threshold=-2, healing_enabled=True, healing_threshold=2)
    with FaultLedger.open(url(tmp_path), policy=policy, background=False) as ledger:

        def worker(n: int) -> None:
            for i in range(120):
                code = f"CODE_{(n + i) % 10}"
                if i % 17 == n:
                    ledger.clear(code, actor=f"test:{n}")
                else:
                    ledger.report(code, "FAILED" if (i + n) % 3 else "PASSED", 1, "",
                                  f"/robot/{n}")

        run_threads(THREADS, worker)
        assert ledger.all_faults() == ledger.state_at(ledger.last_seq)
        report = ledger.verify()
        assert report.ok, report.problems
        live = ledger.all_faults()
    with FaultLedger.open(url(tmp_path)) as reopened:
        assert reopened.all_faults() == live


def test_subscriber_sees_notifications_in_seq_order(tmp_path: Path) -> None:
    policy = Policy(confirmation_threshold=-2, healing_enabled=True, healing_threshold=2)
    received: list[Notification] = []
    with FaultLedger.open(url(tmp_path), policy=policy, background=False) as ledger:
        ledger.subscribe(received.append)

        def worker(n: int) -> None:
            for i in range(150):
                ledger.report(f"CODE_{(n + i) % 12}", "FAILED" if (i + n) % 3 else "PASSED",
                              1, "", f"/robot/{n}")

        run_threads(THREADS, worker)
        history = {r.seq: r for r in ledger.history()}
    seqs = [n.seq for n in received]
    assert len(seqs) > 50
    assert seqs == sorted(seqs)
    assert len(set(seqs)) == len(seqs)
    for notification in received:
        assert history[notification.seq].fault_code == notification.fault.fault_code


def test_subscriber_sees_the_state_after_each_change(tmp_path: Path) -> None:
    """The fault carried by a notification is the replayed state at that seq."""
    received: list[Notification] = []
    with FaultLedger.open(url(tmp_path), policy=Policy(confirmation_threshold=-2),
                          background=False) as ledger:
        ledger.subscribe(received.append)

        def worker(n: int) -> None:
            for i in range(60):
                ledger.report(f"CODE_{(n + i) % 6}", "FAILED", 1 + i % 3, "", f"/robot/{n}")

        run_threads(4, worker)
        sample = received[:: max(1, len(received) // 10)]
        for notification in sample:
            at_seq = {f.fault_code: f for f in ledger.state_at(notification.seq)}
            assert at_seq[notification.fault.fault_code] == notification.fault
