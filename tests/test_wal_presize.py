"""A serving writer gives a new SQLite WAL its working size in zeros at its first write
(store/dialects.py, ``presize_wal``), so that commits overwrite the file instead of making it
longer. The zeros go after the last byte of the file, under the write lock: what other
connections wrote there stays as it was, and SQLite reads no frame out of the zeros."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path

from faultledger import FaultLedger, Policy, ReportRequest
from faultledger.store.dialects import WAL_WORKING_SIZE
from tests.test_disk_full import small_disk

__all__ = ["small_disk"]  # the fixture: a 4 MiB tmpfs (needs root)


def url(path: Path) -> str:
    return f"sqlite:///{path}"


def wal_of(path: Path) -> Path:
    return path.with_name(path.name + "-wal")


def test_a_serving_writer_gives_the_wal_its_working_size_and_a_one_shot_writer_does_not(
        tmp_path: Path) -> None:
    served, once = tmp_path / "served.db", tmp_path / "once.db"
    with FaultLedger.open(url(served), policy=Policy()) as ledger:
        assert ledger.report("LIDAR_TIMEOUT", "FAILED", 2, "", "/lidar").accepted
        assert wal_of(served).stat().st_size == WAL_WORKING_SIZE
    with FaultLedger.open(url(once)) as ledger:
        assert ledger.report("LIDAR_TIMEOUT", "FAILED", 2, "", "/lidar").accepted
        assert 0 < wal_of(once).stat().st_size < WAL_WORKING_SIZE


def test_the_zeros_go_after_another_writers_frames_and_nothing_is_lost(tmp_path: Path
                                                                       ) -> None:
    path = tmp_path / "faults.db"
    first = FaultLedger.open(url(path))  # a one-shot writer: its frames stay in the WAL
    try:
        seqs = [first.report(f"ARM_{i % 3}", "FAILED", 2, "", "/arm").seq for i in range(40)]
        before = wal_of(path).read_bytes()
        assert 0 < len(before) < WAL_WORKING_SIZE
        with FaultLedger.open(url(path), policy=Policy()) as serving:
            seqs += [serving.report("BATTERY_LOW", "FAILED", 3, "", "/power").seq
                     for _ in range(5)]
            after = wal_of(path).read_bytes()
            assert len(after) == WAL_WORKING_SIZE
            assert after[:len(before)] == before  # every byte the first writer wrote
        seqs += [first.report("ARM_0", "PASSED", 2, "", "/arm").seq]
    finally:
        first.close()
    with FaultLedger.open(url(path)) as ledger:
        assert {r.seq for r in ledger.history(kinds=["fault_reported"])} == set(seqs)
        assert ledger.verify().ok


KILLED = textwrap.dedent("""
    import os, signal, sys
    from faultledger import FaultLedger, Policy, ReportRequest
    ledger = FaultLedger.open(sys.argv[1], policy=Policy())
    for i in range(300):
        result = ledger.report("ESTOP_%d" % (i % 7), "FAILED", 3, "", "/base")
        print(result.seq, flush=True)
    os.kill(os.getpid(), signal.SIGKILL)
""")


def test_records_in_a_presized_wal_survive_a_kill(tmp_path: Path) -> None:
    """Killed before any checkpoint: the records are only in the WAL, followed by zeros; the
    next open reads every acknowledged one and no more."""
    path = tmp_path / "faults.db"
    done = subprocess.run([sys.executable, "-c", KILLED, url(path)], capture_output=True,
                          text=True, timeout=120, check=False)
    assert done.returncode == -9, done.stderr
    acknowledged = [int(line) for line in done.stdout.split()]
    assert len(acknowledged) == 300
    assert wal_of(path).stat().st_size == WAL_WORKING_SIZE  # nothing cut it back
    with FaultLedger.open(url(path)) as ledger:
        stored = [r.seq for r in ledger.history(kinds=["fault_reported"])]
        assert stored == acknowledged
        assert ledger.verify().ok


def test_a_wal_longer_than_its_working_size_is_never_cut(tmp_path: Path) -> None:
    """A reader's old snapshot kept SQLite from starting the WAL over, so another writer's
    frames made it longer: the serving writer only ever makes it longer, never shorter."""
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path)) as first:
        first.report("ARM_0", "FAILED", 2, "", "/arm")
        reader = sqlite3.connect(path, isolation_level=None)
        try:
            reader.execute("BEGIN")
            reader.execute("SELECT count(*) FROM events").fetchone()  # holds its snapshot
            burst = [ReportRequest(f"ARM_{i % 50}", "FAILED", 2, "x" * 900, "/arm")
                     for i in range(6_000)]
            assert all(r.accepted for r in first.report_many(burst))
            size = wal_of(path).stat().st_size
            assert size > WAL_WORKING_SIZE
            with FaultLedger.open(url(path), policy=Policy()) as serving:
                assert serving.report("BATTERY_LOW", "FAILED", 3, "", "/power").accepted
                assert wal_of(path).stat().st_size >= size
        finally:
            reader.close()
    with FaultLedger.open(url(path)) as ledger:
        assert len(ledger.history(kinds=["fault_reported"])) == 6_002
        assert ledger.verify().ok


def test_on_a_disk_without_room_for_the_zeros_the_wal_is_cut_back(small_disk: Path) -> None:
    """4 MiB of tmpfs hold the database but not 4 MiB of zeros: the write comes up short,
    the WAL is cut back to its size, and the reports are recorded all the same."""
    path = small_disk / "faults.db"
    with FaultLedger.open(url(path), policy=Policy()) as ledger:
        seqs = [ledger.report(f"ARM_{i % 3}", "FAILED", 2, "", "/arm").seq for i in range(20)]
        assert all(seqs)
        assert wal_of(path).stat().st_size < WAL_WORKING_SIZE
        free = os.statvfs(small_disk)
        assert free.f_bavail * free.f_frsize > 2 * 1024 * 1024  # the zeros gave it back
    with FaultLedger.open(url(path)) as ledger:
        assert [r.seq for r in ledger.history(kinds=["fault_reported"])] == seqs
