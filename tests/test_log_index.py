"""The log's index by fault code (``events_by_code``) is written with the projections, not
with each record: a read by code joins the indexed seqs up to the projections' checkpoint
with the records after it. Whatever the place of the checkpoint, a read by code is the log
filtered by code: nothing missing, nothing twice, in seq order."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faultledger import FaultLedger, VerifyReport
from faultledger.store import event_log, log_index
from faultledger.store.database import Database
from faultledger.store.event_log import RecordFilter
from tests.test_migrations import alembic_on, head, revision_of

CODES = ("ARM_OVERCURRENT", "ARM_STALL", "BATTERY_LOW", "LIDAR_TIMEOUT")


def url(path: Path) -> str:
    return f"sqlite:///{path}"


def seqs_by_code(path: Path, **where: object) -> list[int]:
    """What a read by code finds, through the store (no projections are saved by it)."""
    database = Database(url(path), create=False)
    try:
        with database.reading() as conn:
            return [r.seq for r in event_log.find(conn, RecordFilter(**where))]  # type: ignore[arg-type]
    finally:
        database.dispose()


def coded_seqs(path: Path) -> dict[str, list[int]]:
    """Each code's records, read from the log itself with sqlite3."""
    with sqlite3.connect(path) as conn:
        rows = conn.execute("SELECT fault_code, seq FROM events WHERE fault_code IS NOT NULL "
                            "ORDER BY seq").fetchall()
    found: dict[str, list[int]] = {}
    for code, seq in rows:
        found.setdefault(code, []).append(seq)
    return found


def indexed_up_to(path: Path) -> tuple[int, int]:
    """(the projections' checkpoint, the highest seq in events_by_code)."""
    with sqlite3.connect(path) as conn:
        (checkpoint,) = conn.execute(
            "SELECT seq FROM checkpoints WHERE name = 'projection'").fetchone()
        (indexed,) = conn.execute("SELECT coalesce(max(seq), 0) FROM events_by_code").fetchone()
    return int(checkpoint), int(indexed)


steps = st.lists(st.tuples(st.sampled_from(CODES), st.booleans(), st.booleans()),
                 min_size=1, max_size=40)


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(steps)
def test_a_read_by_code_is_the_log_filtered_by_code(tmp_path_factory: pytest.TempPathFactory,
                                                    given_steps: list[tuple[str, bool, bool]]
                                                    ) -> None:
    """Reports over a few codes; where a step says so the ledger is closed (which saves the
    projections, and indexes every record so far) and opened again."""
    path = tmp_path_factory.mktemp("log") / "faults.db"
    ledger = FaultLedger.open(url(path))
    try:
        for code, failed, reopen in given_steps:
            ledger.report(code, "FAILED" if failed else "PASSED", 2, "", "/arm")
            if reopen:
                ledger.close()
                ledger = FaultLedger.open(url(path))
        expected = coded_seqs(path)
        for code in CODES:
            mine = expected.get(code, [])
            assert [r.seq for r in ledger.history(code=code)] == mine
            assert [r.seq for r in ledger.history(code=code, limit=2)] == mine[:2]
            assert seqs_by_code(path, fault_code=code, descending=True, limit=3) == (
                mine[::-1][:3])
        arm = sorted(seq for code in CODES if code.startswith("ARM_")
                     for seq in expected.get(code, []))
        assert [r.seq for r in ledger.history(codes=["ARM_*"])] == arm
    finally:
        ledger.close()


def test_records_after_the_checkpoint_are_found_before_they_are_indexed(tmp_path: Path
                                                                         ) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path)) as ledger:
        for i in range(6):
            ledger.report(CODES[i % 2], "FAILED", 2, "", "/arm")
    saved, indexed = indexed_up_to(path)
    with FaultLedger.open(url(path)) as ledger:
        for i in range(6):
            ledger.report(CODES[i % 2], "FAILED", 2, "", "/arm")
        # Not saved yet (a save comes every 1,000 records or half a second): the new
        # records are not indexed, and a read by code finds them by their seq.
        assert indexed_up_to(path) == (saved, indexed)
        expected = coded_seqs(path)
        assert [r.seq for r in ledger.history(code=CODES[0])] == expected[CODES[0]]
        assert len(expected[CODES[0]]) == 6
        assert code_index_codes(path) == sorted(expected)
    assert indexed_up_to(path)[1] == max(max(s) for s in coded_seqs(path).values())


def code_index_codes(path: Path) -> list[str]:
    database = Database(url(path), create=False)
    try:
        with database.reading() as conn:
            return log_index.distinct_codes(conn)
    finally:
        database.dispose()


def test_a_checkpoint_moved_back_neither_repeats_nor_loses_records(tmp_path: Path) -> None:
    """Index rows past the checkpoint (a checkpoint put back, e.g. by restoring the
    projections of an older copy) are not read; the next save keeps them and goes on."""
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path)) as ledger:
        for i in range(12):
            ledger.report(CODES[i % 3], "FAILED" if i % 4 else "PASSED", 2, "", "/arm")
    expected = coded_seqs(path)
    with sqlite3.connect(path) as conn:
        (hash_5,) = conn.execute("SELECT hash FROM events WHERE seq = 5").fetchone()
        conn.execute("UPDATE checkpoints SET seq = 5, hash = ? WHERE name = 'projection'",
                     (hash_5,))
    assert indexed_up_to(path)[0] == 5
    for code in CODES[:3]:
        assert seqs_by_code(path, fault_code=code) == expected[code]
    with FaultLedger.open(url(path)) as ledger:  # replays from seq 5 and saves again
        ledger.report(CODES[0], "FAILED", 2, "", "/arm")
        assert [r.seq for r in ledger.history(code=CODES[0])] == (
            [*expected[CODES[0]], ledger.last_seq])
    for code in CODES[:3]:
        assert seqs_by_code(path, fault_code=code) == coded_seqs(path)[code]


def test_the_upgrade_indexes_every_record_of_an_older_log(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path)) as ledger:
        for i in range(9):
            ledger.report(CODES[i % 3], "FAILED", 2, "", "/arm")
    expected = coded_seqs(path)
    alembic_on(path, "downgrade", "0008_alerts")  # the log as 0008 held it
    with sqlite3.connect(path) as conn:
        tables = {row[0] for row in conn.execute("SELECT name FROM sqlite_master")}
    assert "events_by_code" not in tables and "ix_events_fault_code_seq" in tables
    with FaultLedger.open(url(path)) as ledger:  # upgrades
        assert revision_of(path) == head()
        for code in CODES[:3]:
            assert [r.seq for r in ledger.history(code=code)] == expected[code]
    with sqlite3.connect(path) as conn:
        rows = conn.execute("SELECT fault_code, seq FROM events_by_code ORDER BY seq").fetchall()
    assert rows == sorted(((code, seq) for code, seqs in expected.items() for seq in seqs),
                          key=lambda row: row[1])


@pytest.mark.parametrize(("tamper", "words"), [
    ("DELETE FROM events_by_code WHERE seq = 3", "lacks 1 record(s)"),
    ("UPDATE events_by_code SET fault_code = 'BATTERY_LOW' WHERE seq = 4", "lacks 1 record(s)"),
    ("INSERT INTO events_by_code VALUES ('LIDAR_TIMEOUT', 2)", "names 1 record(s)"),
])
def test_verify_compares_the_index_with_the_log(tmp_path: Path, tamper: str, words: str
                                                ) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path)) as ledger:
        for i in range(8):
            ledger.report(CODES[i % 2], "FAILED", 2, "", "/arm")
    result = verified_after(path, tamper)
    assert not result.ok
    assert any(words in problem for problem in result.problems), result.problems


def verified_after(path: Path, tamper: str) -> VerifyReport:
    """``verify`` of a log after one sqlite3 edit of it (checked whole before the edit)."""
    with FaultLedger.open(url(path)) as ledger:
        assert ledger.verify().ok
    with sqlite3.connect(path) as conn:
        conn.execute(tamper)
    with FaultLedger.open(url(path)) as ledger:
        return ledger.verify()


@pytest.mark.parametrize("tamper", [
    "DELETE FROM events_by_code WHERE seq = 3",
    "INSERT INTO events_by_code VALUES ('LIDAR_TIMEOUT', 2)",
])
def test_rebuild_makes_a_damaged_index_again(tmp_path: Path, tamper: str) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path)) as ledger:
        for i in range(8):
            ledger.report(CODES[i % 2], "FAILED", 2, "", "/arm")
    expected = coded_seqs(path)
    with sqlite3.connect(path) as conn:
        conn.execute(tamper)
    with FaultLedger.open(url(path)) as ledger:
        assert not ledger.verify().ok
        ledger.rebuild()
        assert ledger.verify().ok, ledger.verify().problems
        for code in CODES[:2]:
            assert [r.seq for r in ledger.history(code=code)] == expected[code]
