"""The log's indexes by time (``events_by_time``) and by event_id (``events_by_id``) are
written with the projections, not with each record (Alembic 0010 dropped
``ix_events_occurred_at`` and the UNIQUE constraint on ``events.event_id``).

Whatever the place of the checkpoint, a read bounded by time is the log filtered by
``occurred_at`` in [since, until): nothing missing, nothing twice, in seq order; a report
repeating an explicit event_id is answered ``duplicate`` and stores nothing, whether the
first one is indexed yet or not, in this process or another. The upgrade indexes every
record of an older log and leaves the records as they were; ``verify`` finds an index that
differs from the log, and a log that repeats an event_id; ``rebuild`` makes a damaged index
again.
"""

from __future__ import annotations

import sqlite3
import threading
import time
import uuid
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faultledger import FaultLedger, ReportRequest, ReportResult, VerifyReport
from faultledger.domain.clock import to_ns
from faultledger.domain.events import FaultReported, LogRecord
from faultledger.domain.types import EventType
from faultledger.service import audit
from faultledger.store import event_log
from faultledger.store.database import Database
from faultledger.store.event_log import RecordFilter
from tests.test_log_index import url, verified_after
from tests.test_migrations import alembic_on, head, revision_of

CODES = ("ARM_OVERCURRENT", "BATTERY_LOW", "LIDAR_TIMEOUT")
BASE = datetime(2026, 1, 5, 12, 0, tzinfo=UTC)
"""Reports happened before this, at the reporter's times (not in seq order)."""
BASE_NS = to_ns(BASE)
SECOND = 1_000_000_000
IDS = tuple(str(uuid.UUID(int=n, version=4)) for n in (11, 22, 33))
"""Explicit event_ids a property's reports may repeat."""


def at(seconds_before: int) -> datetime:
    return BASE - timedelta(seconds=seconds_before)


def report(ledger: FaultLedger, seconds_before: int, event_id: str | None = None,
           code: str = CODES[0]) -> ReportResult:
    return ledger.report(code, "FAILED", 2, "", "/arm", at=at(seconds_before),
                         event_id=event_id)


def save_projections(ledger: FaultLedger) -> None:
    """Save the projections now, as the background tick or the 1,000th record would: a
    read of the saved projections saves them first (``FaultLedger._saved``)."""
    ledger.transitions()


def log_rows(path: Path, sql: str, *args: object) -> list[tuple[Any, ...]]:
    with sqlite3.connect(path) as conn:
        return conn.execute(sql, args).fetchall()


def timed_seqs(path: Path, since_ns: int | None, until_ns: int | None) -> list[int]:
    """The records with occurred_at in [since, until), read from the log itself."""
    return [seq for seq, occurred in log_rows(
                path, "SELECT seq, occurred_at_ns FROM events ORDER BY seq")
            if (since_ns is None or occurred >= since_ns)
            and (until_ns is None or occurred < until_ns)]


def record_count(path: Path) -> int:
    return int(log_rows(path, "SELECT count(*) FROM events")[0][0])


def report_count(path: Path) -> int:
    return int(log_rows(path, "SELECT count(*) FROM events WHERE kind = 'fault_reported'")
               [0][0])


def indexed_up_to(path: Path, table: str) -> tuple[int, int]:
    """(the projections' checkpoint, the highest seq in ``table``)."""
    ((checkpoint,),) = log_rows(path, "SELECT coalesce(max(seq), 0) FROM checkpoints "
                                "WHERE name = 'projection'")  # none before the first save
    ((indexed,),) = log_rows(path, f"SELECT coalesce(max(seq), 0) FROM {table}")
    return int(checkpoint), int(indexed)


def seqs_by_time(path: Path, since_ns: int | None, until_ns: int | None, *,
                 descending: bool = False, limit: int | None = None) -> list[int]:
    """What a read bounded by time finds, through the store (no projections are saved)."""
    database = Database(url(path), create=False)
    try:
        with database.reading() as conn:
            where = RecordFilter(since_ns=since_ns, until_ns=until_ns, descending=descending,
                                 limit=limit)
            return [r.seq for r in event_log.find(conn, where)]
    finally:
        database.dispose()


def assert_reads_by_time_are_the_log(path: Path, ledger: FaultLedger) -> None:
    for since, until in ((BASE_NS - 20 * SECOND, BASE_NS - 5 * SECOND),
                         (None, BASE_NS - 10 * SECOND), (BASE_NS - 3 * SECOND, None),
                         (BASE_NS - 8 * SECOND, BASE_NS - 8 * SECOND + 1)):
        expected = timed_seqs(path, since, until)
        assert [r.seq for r in ledger.history(since=since, until=until)] == expected
        assert seqs_by_time(path, since, until, descending=True) == expected[::-1]


def append_behind_the_writer(path: Path, event_ids: list[str],
                             seconds_before: list[int] | None = None) -> None:
    """Append reports with these event_ids through the store, as a writer that did not check
    them would (nor save the projections): the hash chain stays valid."""
    database = Database(url(path), create=False)
    try:
        with database.writing() as conn:
            seq, prev_hash = event_log.head(conn)
            now = time.time_ns()
            times = [now if seconds_before is None else to_ns(at(seconds_before[i]))
                     for i in range(len(event_ids))]
            event = FaultReported("BATTERY_LOW", EventType.FAILED, 2, "", "/power")
            event_log.append(conn, [LogRecord(seq + i, event_id, event, times[i - 1], now)
                                    for i, event_id in enumerate(event_ids, 1)], prev_hash)
    finally:
        database.dispose()


def stored_verify(path: Path) -> VerifyReport:
    """``verify`` of a log no writer opened (so no save moves the checkpoint first)."""
    database = Database(url(path), create=False)
    try:
        return audit.verify(database)
    finally:
        database.dispose()


# -- reads by time and repeated event_ids, whatever the checkpoint --------------------------------
step = st.tuples(st.integers(0, 12),                        # seconds before BASE
                 st.one_of(st.none(), st.sampled_from(IDS)),  # explicit event_id
                 st.sampled_from(("", "save", "reopen")))
bound = st.one_of(st.none(), st.tuples(st.integers(0, 13), st.sampled_from((-1, 0, 1))))
query = st.tuples(bound, bound, st.booleans(), st.one_of(st.none(), st.integers(1, 4)))


def bound_ns(given_bound: tuple[int, int] | None) -> int | None:
    return None if given_bound is None else BASE_NS - given_bound[0] * SECOND + given_bound[1]


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(step, min_size=1, max_size=30), st.lists(query, min_size=1, max_size=6))
def test_a_read_by_time_is_the_log_filtered_by_time(
        tmp_path_factory: pytest.TempPathFactory,
        given_steps: list[tuple[int, str | None, str]],
        queries: list[tuple[tuple[int, int] | None, tuple[int, int] | None, bool, int | None]]
        ) -> None:
    """Reports at random past times, some with an explicit event_id that may repeat an
    earlier one; where a step says so the projections are saved (indexing every record so
    far), or the ledger is closed and opened again. The reads come last, while the records
    since the last save are not indexed."""
    path = tmp_path_factory.mktemp("log") / "faults.db"
    ledger = FaultLedger.open(url(path), background=False)
    accepted_ids: set[str] = set()
    try:
        for seconds_before, event_id, then in given_steps:
            before = report_count(path)
            result = report(ledger, seconds_before, event_id, CODES[seconds_before % 3])
            repeated = event_id in accepted_ids
            assert result.accepted and result.duplicate == repeated, result
            assert report_count(path) == before + (0 if repeated else 1)
            if event_id is not None:
                accepted_ids.add(event_id)
            if then == "save":
                save_projections(ledger)
            elif then == "reopen":
                ledger.close()
                ledger = FaultLedger.open(url(path), background=False)
        explicit = log_rows(path, "SELECT event_id FROM events WHERE event_id IN (?, ?, ?)",
                            *IDS)
        assert sorted(e for (e,) in explicit) == sorted(accepted_ids)  # each once
        for since_bound, until_bound, descending, limit in queries:
            since, until = bound_ns(since_bound), bound_ns(until_bound)
            expected = timed_seqs(path, since, until)
            newest_first = expected[::-1] if descending else expected
            assert [r.seq for r in ledger.history(since=since, until=until)] == expected
            assert [r.seq for r in ledger.history(since=since, until=until, limit=limit)] == (
                expected[:limit])
            assert seqs_by_time(path, since, until, descending=descending, limit=limit) == (
                newest_first[:limit])
            assert [r.seq for r in audit.export_history(
                ledger, since=since, until=until, descending=descending)] == newest_first
            assert audit.count_history(ledger, since=since, until=until) == len(expected)
    finally:
        ledger.close()


def test_records_after_the_checkpoint_are_found_by_time_before_they_are_indexed(
        tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path)) as ledger:
        for i in range(6):
            report(ledger, (i * 7) % 12)
    saved, indexed = indexed_up_to(path, "events_by_time")
    assert saved == indexed == record_count(path)
    with FaultLedger.open(url(path)) as ledger:
        for i in range(6):
            report(ledger, (i * 5) % 12)
        # Not saved yet (a save comes every 1,000 records or half a second): the new
        # records are not indexed, and a read by time finds them by their seq.
        assert indexed_up_to(path, "events_by_time") == (saved, indexed)
        assert indexed_up_to(path, "events_by_id") == (saved, indexed)
        found = [r.seq for r in ledger.history(since=BASE_NS - 5 * SECOND, until=BASE_NS)]
        assert found == timed_seqs(path, BASE_NS - 5 * SECOND, BASE_NS)
        assert any(seq > saved for seq in found) and any(seq <= saved for seq in found)
        assert_reads_by_time_are_the_log(path, ledger)
    assert indexed_up_to(path, "events_by_time")[1] == record_count(path)


# -- repeated event_ids ---------------------------------------------------------------------------
def test_a_repeated_event_id_is_recognised_before_any_save(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    first, second = str(uuid.uuid4()), str(uuid.uuid4())
    with FaultLedger.open(url(path)) as ledger:
        original = report(ledger, 3, first)
        assert original.accepted and not original.duplicate and original.seq is not None
        count = record_count(path)
        assert indexed_up_to(path, "events_by_id")[1] < original.seq  # not indexed yet
        again = report(ledger, 4, first)
        assert again.accepted and again.duplicate and again.seq is None
        # Twice in one group commit: the second is the repeat.
        both = ledger.report_many([ReportRequest(CODES[1], "FAILED", 2, "", "/arm",
                                                 at(1), second)] * 2)
        assert [(r.accepted, r.duplicate) for r in both] == [(True, False), (True, True)]
        assert record_count(path) == count + 1
        assert indexed_up_to(path, "events_by_id")[0] < original.seq
    assert log_rows(path, "SELECT count(*) FROM events WHERE event_id IN (?, ?)",
                    first, second) == [(2,)]


def test_a_repeated_event_id_is_recognised_once_indexed(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    event_id = str(uuid.uuid4())
    with FaultLedger.open(url(path)) as ledger:
        original = report(ledger, 3, event_id)
        assert original.seq is not None
        report(ledger, 2)
        save_projections(ledger)
        assert indexed_up_to(path, "events_by_id")[0] > original.seq
        assert log_rows(path, "SELECT seq FROM events_by_id WHERE event_id = ?",
                        event_id) == [(original.seq,)]
        count = record_count(path)
        again = report(ledger, 1, event_id)
        assert again.accepted and again.duplicate
        assert record_count(path) == count


def test_a_repeated_event_id_is_recognised_after_reopening(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    event_id = str(uuid.uuid4())
    with FaultLedger.open(url(path)) as ledger:
        report(ledger, 3, event_id)
    count = record_count(path)
    with FaultLedger.open(url(path)) as ledger:
        again = report(ledger, 3, event_id)
        assert again.accepted and again.duplicate, again
        again = report(ledger, 3, event_id.upper())  # the same UUID, spelt otherwise
        assert again.accepted and again.duplicate, again
        assert record_count(path) == count


def test_a_repeated_event_id_is_recognised_by_another_writer(tmp_path: Path) -> None:
    """Two ledgers open on one file: each checks the other's records, saved or not."""
    path = tmp_path / "faults.db"
    ids = [str(uuid.uuid4()) for _ in range(3)]
    with FaultLedger.open(url(path)) as first, FaultLedger.open(url(path)) as second:
        assert not report(first, 1, ids[0]).duplicate
        assert report(second, 2, ids[0]).duplicate  # not indexed yet
        assert not report(second, 3, ids[1]).duplicate
        assert report(first, 4, ids[1]).duplicate
        save_projections(first)  # both now indexed
        assert indexed_up_to(path, "events_by_id")[0] == record_count(path)
        assert report(second, 5, ids[0]).duplicate
        assert report(second, 5, ids[1]).duplicate

        results: dict[str, list[ReportResult]] = {"first": [], "second": []}

        def race(ledger: FaultLedger, name: str) -> None:
            for event_id in [*ids, *ids]:
                results[name].append(report(ledger, 6, event_id))

        threads = [threading.Thread(target=race, args=(ledger, name))
                   for ledger, name in ((first, "first"), (second, "second"))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        stored = [r for found in results.values() for r in found if not r.duplicate]
        assert all(r.accepted for found in results.values() for r in found)
        assert [r.event_id for r in stored] == [ids[2]]
    assert log_rows(path, "SELECT event_id, count(*) FROM events WHERE event_id IN "
                    "(?, ?, ?) GROUP BY event_id", *ids) == sorted((i, 1) for i in ids)


# -- the upgrade ----------------------------------------------------------------------------------
def test_a_repeated_event_id_is_recognised_when_the_checkpoint_is_behind_the_writer(
        tmp_path: Path) -> None:
    """A writer knows the ids of the records after the checkpoint it saved (its own, those
    it caught up with). Should the checkpoint be behind that (moved back, or a save at open
    that failed) and a record before it not indexed, the writer reads the log's tail."""
    path = tmp_path / "faults.db"
    early = str(uuid.uuid4())
    with FaultLedger.open(url(path)) as ledger:
        report(ledger, 9)
        report(ledger, 8, early)
    (early_seq,) = log_rows(path, "SELECT seq FROM events WHERE event_id = ?", early)[0]
    with FaultLedger.open(url(path)) as ledger:  # everything before it is indexed at open
        assert indexed_up_to(path, "events_by_id")[0] >= early_seq
        with sqlite3.connect(path) as conn:  # as if that record had never been indexed
            conn.execute("UPDATE checkpoints SET seq = ? WHERE name = 'projection'",
                         (early_seq - 1,))
            conn.execute("DELETE FROM events_by_id WHERE event_id = ?", (early,))
        assert report(ledger, 7, early).duplicate
    assert log_rows(path, "SELECT count(*) FROM events WHERE event_id = ?", early) == [(1,)]


def test_the_upgrade_indexes_every_record_of_an_older_log(tmp_path: Path) -> None:
    """A 0009 log with records after its projections' checkpoint (as a crash leaves them) is
    upgraded on open: every record is indexed and kept exactly as it was."""
    path = tmp_path / "faults.db"
    explicit = [str(uuid.uuid4()) for _ in range(6)]
    with FaultLedger.open(url(path)) as ledger:
        for i in range(10):
            report(ledger, (i * 7) % 12, explicit[i // 3] if i % 3 == 0 else None,
                   CODES[i % 3])
    append_behind_the_writer(path, [*explicit[4:], str(uuid.uuid4())], [9, 2, 5])
    records = log_rows(path, "SELECT * FROM events ORDER BY seq")
    assert indexed_up_to(path, "events_by_time") == (len(records) - 3, len(records) - 3)
    alembic_on(path, "downgrade", "0009_events_by_code")  # the log as 0009 held it
    names = {name for (name,) in log_rows(path, "SELECT name FROM sqlite_master")}
    assert {"ix_events_occurred_at", "sqlite_autoindex_events_1"} <= names
    assert not names & {"events_by_time", "events_by_id"}
    assert ("sqlite_autoindex_events_1", 1) in [
        (row[1], row[2]) for row in log_rows(path, "PRAGMA index_list(events)")]
    assert log_rows(path, "SELECT * FROM events ORDER BY seq") == records

    with FaultLedger.open(url(path)) as ledger:  # upgrades
        assert revision_of(path) == head()
        assert_reads_by_time_are_the_log(path, ledger)
        count = record_count(path)
        for event_id in explicit:  # indexed by the upgrade, or after the checkpoint
            assert report(ledger, 1, event_id).duplicate
        assert record_count(path) == count
        assert ledger.verify().ok, ledger.verify().problems
    assert log_rows(path, "SELECT * FROM events ORDER BY seq") == records
    names = {name for (name,) in log_rows(path, "SELECT name FROM sqlite_master")}
    assert {"events_by_time", "events_by_id"} <= names
    assert log_rows(path, "PRAGMA index_list(events)") == []  # no index, no UNIQUE
    assert "UNIQUE" not in log_rows(
        path, "SELECT sql FROM sqlite_master WHERE name = 'events'")[0][0].upper()
    assert sorted(log_rows(path, "SELECT occurred_at_ns, seq FROM events_by_time")) == sorted(
        (row[6], row[0]) for row in records)
    assert sorted(log_rows(path, "SELECT event_id, seq FROM events_by_id")) == sorted(
        (row[1], row[0]) for row in records)


# -- a checkpoint moved back ----------------------------------------------------------------------
def test_a_checkpoint_moved_back_neither_repeats_nor_loses_records_by_time_or_id(
        tmp_path: Path) -> None:
    """Index rows past the checkpoint (a checkpoint put back, e.g. by restoring the
    projections of an older copy) are not read; the next save keeps them and goes on."""
    path = tmp_path / "faults.db"
    ids = [str(uuid.uuid4()) for _ in range(12)]
    with FaultLedger.open(url(path)) as ledger:
        for i in range(12):
            report(ledger, (i * 5) % 12, ids[i])
    with sqlite3.connect(path) as conn:
        (hash_5,) = conn.execute("SELECT hash FROM events WHERE seq = 5").fetchone()
        conn.execute("UPDATE checkpoints SET seq = 5, hash = ? WHERE name = 'projection'",
                     (hash_5,))
    assert indexed_up_to(path, "events_by_time") == (5, record_count(path))
    for since, until in ((BASE_NS - 6 * SECOND, BASE_NS), (None, BASE_NS - 4 * SECOND)):
        expected = timed_seqs(path, since, until)
        assert seqs_by_time(path, since, until) == expected
        assert seqs_by_time(path, since, until, descending=True, limit=3) == (
            expected[::-1][:3])
    with FaultLedger.open(url(path)) as ledger:  # replays from seq 5 and saves again
        count = record_count(path)
        assert all(report(ledger, 2, event_id).duplicate for event_id in ids)
        assert record_count(path) == count
        report(ledger, 2)
        assert_reads_by_time_are_the_log(path, ledger)
    records = log_rows(path, "SELECT seq, event_id, occurred_at_ns FROM events")
    assert indexed_up_to(path, "events_by_time") == (len(records), len(records))
    assert sorted(log_rows(path, "SELECT occurred_at_ns, seq FROM events_by_time")) == sorted(
        (occurred, seq) for seq, _, occurred in records)
    assert sorted(log_rows(path, "SELECT event_id, seq FROM events_by_id")) == sorted(
        (event_id, seq) for seq, event_id, _ in records)


# -- verify ---------------------------------------------------------------------------------------
STRAY_ID = str(uuid.UUID(int=99, version=4))


def ten_reports(path: Path) -> list[str]:
    """A closed log (every record indexed) of ten reports with explicit event_ids at seqs
    3..12 (seqs 1 and 2 are the log's identity and policy)."""
    ids = [str(uuid.uuid4()) for _ in range(10)]
    with FaultLedger.open(url(path)) as ledger:
        results = [report(ledger, (i * 7) % 12, ids[i], CODES[i % 3]) for i in range(10)]
    assert [r.seq for r in results] == list(range(3, 13))
    return ids


INDEX_TAMPERING = [
    ("DELETE FROM events_by_time WHERE seq = 4",
     "the index by time lacks 1 record(s) up to the checkpoint"),
    ("UPDATE events_by_time SET occurred_at_ns = occurred_at_ns + 1 WHERE seq = 4",
     "the index by time names 1 record(s) the log does not hold with that occurred_at_ns"),
    ("UPDATE events_by_time SET occurred_at_ns = occurred_at_ns + 1 WHERE seq = 4",
     "the index by time lacks 1 record(s) up to the checkpoint"),
    ("INSERT INTO events_by_time VALUES (123, 2)",
     "the index by time names 1 record(s) the log does not hold with that occurred_at_ns"),
    ("DELETE FROM events_by_id WHERE seq = 4",
     "the index by event_id lacks 1 record(s) up to the checkpoint"),
    (f"INSERT INTO events_by_id VALUES ('{STRAY_ID}', 2)",
     "the index by event_id names 1 record(s) the log does not hold with that event_id"),
    ("UPDATE events_by_id SET seq = 5 WHERE seq = 4",
     "the index by event_id names 1 record(s) the log does not hold with that event_id"),
]


@pytest.mark.parametrize(("tamper", "words"), INDEX_TAMPERING)
def test_verify_compares_the_indexes_with_the_log(tmp_path: Path, tamper: str, words: str
                                                  ) -> None:
    path = tmp_path / "faults.db"
    ten_reports(path)
    result = verified_after(path, tamper)
    assert not result.ok
    assert words in result.problems, result.problems


@pytest.mark.parametrize("tamper", sorted({tamper for tamper, _ in INDEX_TAMPERING}))
def test_verify_names_no_repeated_event_id_where_the_log_repeats_none(
        tmp_path: Path, tamper: str) -> None:
    """A damaged index is the index's problem: the log's records still repeat no event_id."""
    path = tmp_path / "faults.db"
    ten_reports(path)
    with sqlite3.connect(path) as conn:
        conn.execute(tamper)
    assert log_rows(path, "SELECT count(*) - count(DISTINCT event_id) FROM events") == [(0,)]
    with FaultLedger.open(url(path)) as ledger:
        result = ledger.verify()
    assert not result.ok
    assert not [p for p in result.problems if "repeat the event_id" in p], result.problems


def test_verify_finds_a_repeated_event_id_under_a_valid_hash_chain(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    ids = ten_reports(path)
    append_behind_the_writer(path, [ids[4]])
    with FaultLedger.open(url(path)) as ledger:  # indexes the new record (a save at open)
        result = ledger.verify()
    assert result.problems and not result.ok
    assert not [p for p in result.problems if "hash" in p], result.problems
    assert "1 record(s) repeat the event_id of an earlier one" in result.problems, result.problems


@pytest.mark.parametrize(("appended", "reopen", "repeats"), [
    pytest.param(["indexed"], False, 1, id="one-copy-of-an-indexed-id-after-the-checkpoint"),
    pytest.param(["new", "new"], False, 1, id="two-copies-of-a-new-id-after-the-checkpoint"),
    pytest.param(["indexed", "indexed"], False, 2,
                 id="two-copies-of-an-indexed-id-after-the-checkpoint"),
    pytest.param(["new", "new", "new"], False, 2,
                 id="three-copies-of-a-new-id-after-the-checkpoint"),
    pytest.param(["indexed", "indexed"], True, 2, id="two-copies-of-an-indexed-id-indexed"),
    pytest.param(["new", "new", "new"], True, 2, id="three-copies-of-a-new-id-indexed"),
])
def test_verify_counts_each_record_that_repeats_an_event_id(
        tmp_path: Path, appended: list[str], reopen: bool, repeats: int) -> None:
    """The records appended behind the writer repeat the id of a record up to the
    checkpoint ("indexed") or one new id; they are after the checkpoint, or indexed by
    a save at open ("reopen"). N records sharing an id: N - 1 of them repeat another."""
    path = tmp_path / "faults.db"
    ids = ten_reports(path)
    new_id = str(uuid.uuid4())
    append_behind_the_writer(path, [ids[4] if a == "indexed" else new_id for a in appended])
    if reopen:
        FaultLedger.open(url(path)).close()
        assert indexed_up_to(path, "events_by_time")[0] == record_count(path)
    else:
        assert indexed_up_to(path, "events_by_time")[0] < record_count(path)
    result = stored_verify(path)
    assert not result.ok
    assert f"{repeats} record(s) repeat the event_id of an earlier one" in result.problems, (
        result.problems)


# -- rebuild --------------------------------------------------------------------------------------
@pytest.mark.parametrize("tamper", [
    "DELETE FROM events_by_time WHERE seq = 4",
    "INSERT INTO events_by_time VALUES (123, 2)",
    "DELETE FROM events_by_id WHERE seq = 4",
    f"INSERT INTO events_by_id VALUES ('{STRAY_ID}', 2)",
])
def test_rebuild_makes_a_damaged_index_again(tmp_path: Path, tamper: str) -> None:
    path = tmp_path / "faults.db"
    ids = ten_reports(path)
    with sqlite3.connect(path) as conn:
        conn.execute(tamper)
    with FaultLedger.open(url(path)) as ledger:
        assert not ledger.verify().ok
        ledger.rebuild()
        assert ledger.verify().ok, ledger.verify().problems
        assert_reads_by_time_are_the_log(path, ledger)
        count = record_count(path)
        assert all(report(ledger, 1, event_id).duplicate for event_id in ids)
        assert not report(ledger, 1, STRAY_ID).duplicate
        assert record_count(path) == count + 1
    records = log_rows(path, "SELECT seq, event_id, occurred_at_ns FROM events")
    assert sorted(log_rows(path, "SELECT occurred_at_ns, seq FROM events_by_time")) == sorted(
        (occurred, seq) for seq, _, occurred in records)
    assert sorted(log_rows(path, "SELECT event_id, seq FROM events_by_id")) == sorted(
        (event_id, seq) for seq, event_id, _ in records)
