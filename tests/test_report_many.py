"""FaultLedger.report_many: a burst of reports in one call, each answered as report() would."""

from __future__ import annotations

import threading
import uuid
from pathlib import Path

from faultledger import Fault, FaultLedger, ReportRequest
from faultledger.domain.events import FaultReported


def url(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'faults.db'}"


def test_results_match_requests_in_order_with_rejections_in_place(tmp_path: Path) -> None:
    with FaultLedger.open(url(tmp_path)) as ledger:
        results = ledger.report_many([
            ReportRequest("ARM_STALL", "FAILED", 2, "first", "/arm"),
            ReportRequest("BAD CODE", "FAILED", 2, "", "/arm"),
            ReportRequest("ARM_STALL", "PASSED", 0, "", "/arm"),
            ReportRequest("GRIPPER_SLIP", "FAILED", 9, "", "/gripper"),
            ReportRequest("GRIPPER_SLIP", "FAILED", 1, "", "/gripper"),
        ])
        assert [r.accepted for r in results] == [True, False, True, False, True]
        assert results[1].message == ("fault_code contains invalid character ' '. Only "
                                      "alphanumeric, underscore, hyphen, and dot are allowed")
        assert "severity" in results[3].message
        reported = ledger.history(kinds=["fault_reported"])
        assert [r.seq for r in results if r.accepted] == [r.seq for r in reported]
        events = [r.event for r in reported if isinstance(r.event, FaultReported)]
        assert [(e.fault_code, e.description) for e in events] == [
            ("ARM_STALL", "first"), ("ARM_STALL", ""), ("GRIPPER_SLIP", "")]


def test_a_burst_equals_the_same_reports_made_one_by_one(tmp_path: Path) -> None:
    burst = [ReportRequest(f"CODE_{i % 7}", "FAILED" if i % 3 else "PASSED", i % 4, f"d{i}",
                           f"/src/{i % 5}") for i in range(200)]
    with FaultLedger.open(f"sqlite:///{tmp_path / 'burst.db'}") as together:
        together.report_many(burst)
        faults_together = together.all_faults()
        assert together.verify().ok
    with FaultLedger.open(f"sqlite:///{tmp_path / 'single.db'}") as alone:
        for request in burst:
            alone.report(*request)
        faults_alone = alone.all_faults()

    def comparable(faults: list[Fault]) -> list[Fault]:
        return [f._replace(first_occurred_ns=0, last_occurred_ns=0, last_passed_ns=0,
                           first_ever_ns=0, confirmed_ns=0)
                for f in faults]

    assert comparable(faults_together) == comparable(faults_alone)


def test_an_event_id_repeated_inside_one_burst_is_stored_once(tmp_path: Path) -> None:
    key = str(uuid.uuid4())
    with FaultLedger.open(url(tmp_path)) as ledger:
        results = ledger.report_many([
            ReportRequest("ESTOP", "FAILED", 3, "press", "/hw", event_id=key),
            ReportRequest("ESTOP", "FAILED", 3, "press", "/hw", event_id=key),
        ])
        assert [(r.accepted, r.duplicate) for r in results] == [(True, False), (True, True)]
        assert [r.event_id for r in ledger.history(kinds=["fault_reported"])] == [key]


def test_bursts_from_several_threads_interleave_without_loss(tmp_path: Path) -> None:
    threads, bursts, size = 4, 25, 8
    with FaultLedger.open(url(tmp_path)) as ledger:
        ids: list[list[str]] = [[] for _ in range(threads)]
        barrier = threading.Barrier(threads)

        def work(n: int) -> None:
            barrier.wait()
            for _ in range(bursts):
                requests = [ReportRequest(f"T{n}_C{i}", "FAILED", 1, "", f"/t{n}",
                                          event_id=str(uuid.uuid4())) for i in range(size)]
                results = ledger.report_many(requests)
                assert all(r.accepted and not r.duplicate for r in results)
                ids[n].extend(r.event_id or "" for r in results)

        pool = [threading.Thread(target=work, args=(n,)) for n in range(threads)]
        for thread in pool:
            thread.start()
        for thread in pool:
            thread.join(timeout=60)
        assert not any(t.is_alive() for t in pool)
        first = ledger.last_seq - threads * bursts * size + 1
        history = ledger.history(kinds=["fault_reported"])
        assert [r.seq for r in history] == list(range(first, ledger.last_seq + 1))
        assert sorted(r.event_id for r in history) == sorted(i for n in ids for i in n)
        for n in range(threads):  # each thread's reports keep their order
            mine = [r.event_id for r in history if r.event_id in set(ids[n])]
            assert mine == ids[n]
        assert ledger.verify().ok


def test_an_empty_burst_records_nothing(tmp_path: Path) -> None:
    with FaultLedger.open(url(tmp_path)) as ledger:
        before = ledger.last_seq
        assert ledger.report_many([]) == []
        assert ledger.last_seq == before
