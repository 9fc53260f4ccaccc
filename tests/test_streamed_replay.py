"""A replay reads the log as one streamed statement (``event_log.read_to_end``): on
PostgreSQL the rows come while the replay works on those before. On both databases a
replay over several chunks of rows equals the records one by one, and a replay that stops
at a record it cannot read leaves its connection usable: the rest of the rows is read and
dropped, where cancelling the statement would abort the transaction under the next query.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
from sqlalchemy import create_engine, text

from faultledger import FaultLedger, Policy, ReportRequest
from faultledger.domain.integrity import GENESIS_HASH, record_hash
from faultledger.errors import DamagedDatabaseError
from faultledger.service.restore import replay
from faultledger.store import event_log, fastpath
from faultledger.store.database import Database
from faultledger.store.schema import PROJECTION_CHECKPOINT

RECORDS = 2 * event_log.READ_CHUNK + 700
"""More records than two chunks of the stream, the last one partial."""
DAMAGED_SEQ = 1234


def build(url: str) -> FaultLedger:
    ledger = FaultLedger.open(url, policy=Policy())
    reports = [ReportRequest(f"CODE_{n % 37}", "FAILED" if n % 3 else "PASSED", n % 4, "",
                             f"/robot/{n % 5}") for n in range(RECORDS)]
    for start in range(0, RECORDS, 500):
        assert all(r.accepted for r in ledger.report_many(reports[start:start + 500]))
    return ledger


def damage(url: str, seq: int) -> None:
    """A payload no code can read at ``seq``, every hash and the checkpoints' recomputed:
    the chain holds, the replay fails there."""
    engine = create_engine(url)
    with engine.begin() as conn:
        conn.execute(text("UPDATE events SET payload = 'not json' WHERE seq = :seq"),
                     {"seq": seq})
        previous = GENESIS_HASH
        rows = conn.execute(text(
            "SELECT seq, event_id, kind, fault_code, source_id, payload, occurred_at_ns, "
            "recorded_at_ns, schema_version FROM events ORDER BY seq")).all()
        for row in rows:
            previous = record_hash(previous, *row)
            conn.execute(text("UPDATE events SET hash = :hash WHERE seq = :seq"),
                         {"hash": previous, "seq": row[0]})
        conn.execute(text("UPDATE checkpoints SET hash = :hash WHERE name = :name"),
                     {"hash": previous, "name": PROJECTION_CHECKPOINT})
    engine.dispose()


def test_a_streamed_replay_is_the_records_one_by_one(fresh_url: Callable[[str], str]) -> None:
    url = fresh_url("faults")
    with build(url) as ledger:
        before = ledger.all_faults()
        head = ledger.last_seq
        assert ledger.rebuild() == head
        assert ledger.all_faults() == before
    db = Database(url)
    try:
        with db.reading() as conn:
            streamed = list(event_log.read_to_end(conn, after_seq=100, upto_seq=head - 50))
            paged = list(event_log.read(conn, after_seq=100, upto_seq=head - 50))
            everything = [r.seq for r in event_log.read_to_end(conn)]
            replayed, _ = replay(conn)
    finally:
        db.dispose()
    assert streamed == paged
    assert [r.seq for r in streamed] == list(range(101, head - 49))
    assert everything == list(range(1, head + 1))
    assert {f.fault_code: f for f in replayed.committed()} == {f.fault_code: f for f in before}


def test_a_replay_stopped_by_a_damaged_record_leaves_the_connection_usable(
        fresh_url: Callable[[str], str]) -> None:
    url = fresh_url("faults")
    with build(url) as ledger:
        head = ledger.last_seq
    damage(url, DAMAGED_SEQ)
    db = Database(url)
    try:
        with db.reading() as conn:
            reading = event_log.read_to_end(conn)
            with pytest.raises(Exception):  # noqa: B017 (the decoder's own error)
                for _ in reading:
                    pass
            assert event_log.head(conn)[0] == head  # the same transaction answers
    finally:
        db.dispose()
    ledger = FaultLedger.open(url)
    try:
        first = ledger.verify()
        assert not first.ok
        assert first.first_bad_seq == DAMAGED_SEQ
        with pytest.raises(DamagedDatabaseError, match=f"seq {DAMAGED_SEQ}"):
            ledger.state_at(head)
        assert ledger.verify() == first  # the pool's connections still answer
        assert len(ledger.history(limit=5)) == 5
    finally:
        ledger.close()


MANY_ROWS = {
    "postgresql": "SELECT n FROM generate_series(1, :n) AS n",
    "sqlite": "WITH RECURSIVE c(n) AS (SELECT 1 UNION ALL SELECT n + 1 FROM c WHERE n < :n) "
              "SELECT n FROM c",
}


def test_a_stream_stopped_early_leaves_its_transaction_usable(
        fresh_url: Callable[[str], str]) -> None:
    """Far more rows than the server has sent when the reader stops: closing the stream
    there would cancel the statement (PostgreSQL: the transaction is aborted)."""
    url = fresh_url("faults")
    FaultLedger.open(url).close()
    db = Database(url)
    try:
        with db.reading() as conn:
            rows = fastpath.stream(conn, text(MANY_ROWS[conn.dialect.name]), {"n": 2_000_000},
                                   1000)
            assert [next(rows) for _ in range(3)] == [(1,), (2,), (3,)]
            rows.close()
            assert conn.execute(text("SELECT 41 + 1")).scalar() == 42
    finally:
        db.dispose()
