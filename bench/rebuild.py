"""Replay speed of FaultLedger.rebuild over a large log vs a bare sqlite3 read + json.loads.

``--postgresql`` also copies the log into a PostgreSQL database (a server started here, as the
tests do: tests/pg_server.py) and measures the rebuild there against a bare psycopg read +
json.loads of the same rows.
"""

from __future__ import annotations

import argparse
import gc
import json
import sqlite3
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec

from _common import (
    ROOT,
    SCRATCH,
    header,
    plan,
    ratio,
    remove_db,
    report_concurrently,
    scratch_dir,
    url_for,
    verdict,
)
from faultledger import FaultLedger, Policy
from faultledger.domain.projector import Projector
from faultledger.domain.statistics import StatsFold
from faultledger.store import event_log
from faultledger.store.database import Database
from faultledger.store.schema import events, stat_facts

sys.path.insert(0, str(ROOT))
from tests import pg_server  # the tests' server helper

FACT_INDEXES = stat_facts.indexes

TARGET_EVENTS_PER_S = 100_000
TARGET_RATIO = 0.6


def count_events(db: Path) -> int:
    conn = sqlite3.connect(db)
    try:
        return int(conn.execute("SELECT count(*) FROM events").fetchone()[0])
    except sqlite3.Error:
        return 0
    finally:
        conn.close()


def build_log(db: Path, reports: int, n_codes: int, threads: int) -> int:
    """Fill ``db`` through the public API (many threads, large group commits); returns the
    number of records in the log."""
    ledger = FaultLedger.open(url_for(db), policy=Policy(), max_batch=4096)
    try:
        work = plan(reports, n_codes)
        seconds, rejected, _ = report_concurrently(ledger, work, threads,
                                                   progress_every=max(1, reports // 10))
        if rejected:
            raise SystemExit(f"{rejected} reports were rejected while building the log")
        print(f"   built {ledger.last_seq:,} records in {seconds:.1f} s "
              f"({reports / seconds:,.0f} reports/s, {threads} threads, "
              f"{ledger._writer.commits:,} commits)", flush=True)
        return ledger.last_seq
    finally:
        ledger.close()


def ensure_log(db: Path, reports: int, n_codes: int, threads: int) -> int:
    """Reuse ``db`` when it already holds at least ``reports`` records, else build it."""
    have = count_events(db) if db.exists() else 0
    if have >= reports:
        print(f"   reusing {db} ({have:,} records)")
        return have
    remove_db(db)
    print(f"   building a log of {reports:,} reports over {n_codes:,} codes in {db} ...",
          flush=True)
    return build_log(db, reports, n_codes, threads)


def baseline_read(db: Path, loads: Callable[[str], Any] = json.loads) -> tuple[int, float]:
    """The floor of any replay: read every row with sqlite3 and json.loads its payload
    (``loads``: another decoder, for the information line)."""
    start = time.perf_counter()
    conn = sqlite3.connect(db)
    count = 0
    for row in conn.execute("SELECT * FROM events ORDER BY seq"):
        loads(row[5])
        count += 1
    conn.close()
    return count, time.perf_counter() - start


def payload_column(db: Path) -> int:
    conn = sqlite3.connect(db)
    names = [r[1] for r in conn.execute("PRAGMA table_info(events)")]
    conn.close()
    return names.index("payload")


def facts_write(db: Path, into: Path) -> tuple[int, float]:
    """What any rebuild that keeps the statistics writes at least: the statistics facts the
    rebuild of ``db`` wrote (one per report), inserted with raw sqlite3 into an empty table of
    the same schema in a new file, in one transaction (WAL, synchronous=FULL), its indexes
    made after the rows as the rebuild does (store/dialects.py, ``bulk_load``)."""
    source = sqlite3.connect(db)
    table_ddl, = source.execute("SELECT sql FROM sqlite_master WHERE type = 'table' "
                                "AND name = 'stat_facts'").fetchone()
    index_ddl = [sql for (sql,) in source.execute(
        "SELECT sql FROM sqlite_master WHERE type = 'index' AND tbl_name = 'stat_facts' "
        "AND sql IS NOT NULL")]
    rows = source.execute("SELECT * FROM stat_facts").fetchall()
    source.close()
    remove_db(into)
    conn = sqlite3.connect(into, isolation_level=None)
    conn.execute("PRAGMA journal_mode = WAL")
    conn.execute("PRAGMA synchronous = FULL")
    conn.execute(table_ddl)
    marks = ", ".join("?" for _ in rows[0]) if rows else ""
    start = time.perf_counter()
    conn.execute("BEGIN IMMEDIATE")
    conn.executemany(f"INSERT INTO stat_facts VALUES ({marks})", rows)
    for sql in index_ddl:
        conn.execute(sql)
    conn.execute("COMMIT")
    seconds = time.perf_counter() - start
    conn.close()
    remove_db(into)
    return len(rows), seconds


def in_memory_floor(url: str, records: int = 200_000) -> tuple[float, float, float]:
    """The per-record cost of faultledger's own replay work without any I/O: the first
    ``records`` records read and decoded by the store (timed), then applied in memory by a
    fresh projector with statistics and by one without (timed); seconds per record each."""
    db = Database(url, create=False)
    gc.disable()  # as the rebuild does (service/restore.py), for the read too
    try:
        with db.reading() as conn:
            start = time.perf_counter()
            log = list(event_log.read(conn, upto_seq=records))
            read_s = time.perf_counter() - start
        db.dispose()
        start = time.perf_counter()
        Projector(stats=StatsFold()).apply_all(log)
        with_stats = time.perf_counter() - start
        start = time.perf_counter()
        Projector().apply_all(log)
        without = time.perf_counter() - start
    finally:
        gc.enable()
    return read_s / len(log), with_stats / len(log), without / len(log)


def time_rebuild(url: str) -> tuple[int, float]:
    ledger = FaultLedger.open(url)  # no policy: opening writes nothing
    try:
        start = time.perf_counter()
        replayed = ledger.rebuild()
        return replayed, time.perf_counter() - start
    finally:
        ledger.close()


def alternating(rounds: int, baseline: Callable[[], tuple[int, float]],
                rebuild: Callable[[], tuple[int, float]]
                ) -> tuple[tuple[int, float], tuple[int, float]]:
    """``rounds`` alternating runs of the baseline and the rebuild, each round printed; the
    median round of each (by time), so that one slow moment of the VM does not decide."""
    bases: list[tuple[int, float]] = []
    rebuilds: list[tuple[int, float]] = []
    for number in range(1, rounds + 1):
        bases.append(baseline())
        rebuilds.append(rebuild())
        if rounds > 1:
            print(f"   round {number}: baseline {bases[-1][0] / bases[-1][1]:,.0f} events/s, "
                  f"rebuild {rebuilds[-1][0] / rebuilds[-1][1]:,.0f} events/s", flush=True)
    middle = len(bases) // 2
    return (sorted(bases, key=lambda r: r[1])[middle],
            sorted(rebuilds, key=lambda r: r[1])[middle])


def measure(db: Path, rounds: int) -> None:
    column = payload_column(db)
    assert column == 5, f"payload is column {column}; adjust baseline_read"
    baseline_read(db)  # warm the page cache so both sides read from memory
    print()
    (base_n, base_s), (replayed, seconds) = alternating(
        rounds, lambda: baseline_read(db), lambda: time_rebuild(url_for(db)))
    rate, base_rate = replayed / seconds, base_n / base_s
    kept = f", median of {rounds} rounds" if rounds > 1 else ""
    print(f"   baseline: sqlite3 SELECT * + json.loads   {base_rate:>12,.0f} events/s "
          f"({base_n:,} rows in {base_s:.2f} s{kept})")
    print(f"   FaultLedger.rebuild()                       {rate:>12,.0f} events/s "
          f"({replayed:,} records in {seconds:.2f} s{kept})")
    fast_n, fast_s = baseline_read(db, msgspec.json.Decoder().decode)
    print(f"   information: the same read with msgspec's decoder (the store's, parse_json) "
          f"{fast_n / fast_s:,.0f} events/s; the rebuild is {rate / (fast_n / fast_s):.2f}x "
          "that")
    facts, facts_s = facts_write(db, db.with_name(db.name + ".facts"))
    print(f"   raw sqlite3 insert of its {facts:,} statistics facts "
          f"{facts / facts_s:>8,.0f} rows/s ({facts_s:.2f} s; one fact per report, "
          f"{len(FACT_INDEXES)} indexes made after the rows)")
    ceiling = base_s / (base_s + facts_s)
    print(f"   a rebuild that only read, decoded and wrote the facts: at most "
          f"{ceiling:.2f}x the baseline")
    read_us, apply_us, bare_us = (x * 1e6 for x in in_memory_floor(url_for(db)))
    budget_us = base_s / base_n / TARGET_RATIO * 1e6
    print(f"   per record, no I/O (first 200,000 records): the store's read and decode "
          f"{read_us:.2f} µs, apply in memory {apply_us:.2f} µs with statistics "
          f"({bare_us:.2f} µs without)")
    print(f"   the {TARGET_RATIO}x target leaves {budget_us:.2f} µs per record for all of it "
          f"(the baseline's {base_s / base_n * 1e6:.2f} µs / {TARGET_RATIO})")
    print()
    print(f"   rebuild vs baseline                          {ratio(rate, base_rate):>10.2f}x   "
          f"target >= {TARGET_RATIO}x  {verdict(rate / base_rate >= TARGET_RATIO)}")
    print(f"   rebuild absolute (events/s)                  {rate:>10,.0f}   target >= "
          f"{TARGET_EVENTS_PER_S:,}  {verdict(rate >= TARGET_EVENTS_PER_S)}")


COLUMNS = tuple(column.name for column in events.columns)
"""The log's columns, as the schema defines them."""


def copy_to_postgresql(db: Path, url: str) -> int:
    """The SQLite log's records, as they are (same hashes), into a new PostgreSQL log."""
    import psycopg

    FaultLedger.open(url).close()  # the schema
    source = sqlite3.connect(db)
    count = 0
    with psycopg.connect(url.replace("postgresql+psycopg", "postgresql")) as conn:
        with conn.cursor() as cursor, cursor.copy(
                f"COPY events ({', '.join(COLUMNS)}) FROM STDIN") as copy:
            for row in source.execute(f"SELECT {', '.join(COLUMNS)} FROM events ORDER BY seq"):
                copy.write_row(row)
                count += 1
        conn.execute("ANALYZE events")
    source.close()
    return count


def baseline_read_postgresql(url: str) -> tuple[int, float]:
    """The floor of a replay on PostgreSQL: every row through psycopg (a server-side cursor,
    as the log's reads page through it) and json.loads of its payload."""
    import psycopg

    start = time.perf_counter()
    count = 0
    with (psycopg.connect(url.replace("postgresql+psycopg", "postgresql")) as conn,
          conn.cursor(name="scan") as cursor):
        cursor.itersize = 5_000
        cursor.execute("SELECT * FROM events ORDER BY seq")
        for row in cursor:
            json.loads(row[5])
            count += 1
    return count, time.perf_counter() - start


def measure_postgresql(db: Path, rounds: int) -> None:
    print()
    with pg_server.running() as server:
        url = server.database("rebuild")
        copied = copy_to_postgresql(db, url)
        baseline_read_postgresql(url)  # warm the server's cache
        (base_n, base_s), (replayed, seconds) = alternating(
            rounds, lambda: baseline_read_postgresql(url), lambda: time_rebuild(url))
    assert replayed == copied == base_n, (replayed, copied, base_n)
    rate, base_rate = replayed / seconds, base_n / base_s
    kept = f", median of {rounds} rounds" if rounds > 1 else ""
    print(f"   PostgreSQL: psycopg SELECT * + json.loads {base_rate:>12,.0f} events/s "
          f"({base_n:,} rows in {base_s:.2f} s{kept})")
    print(f"   PostgreSQL: FaultLedger.rebuild()           {rate:>12,.0f} events/s "
          f"({replayed:,} records in {seconds:.2f} s{kept})")
    print(f"   PostgreSQL rebuild vs baseline               {ratio(rate, base_rate):>10.2f}x   "
          f"target >= {TARGET_RATIO}x  {verdict(rate / base_rate >= TARGET_RATIO)}")
    print(f"   PostgreSQL rebuild absolute (events/s)       {rate:>10,.0f}   target >= "
          f"{TARGET_EVENTS_PER_S:,}  {verdict(rate >= TARGET_EVENTS_PER_S)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="100,000 reports")
    parser.add_argument("--reports", type=int, default=None,
                        help="reports in the log (default 1,000,000; --quick 100,000)")
    parser.add_argument("--codes", type=int, default=5000)
    parser.add_argument("--threads", type=int, default=48,
                        help="reporting threads used to build the log")
    parser.add_argument("--keep", type=Path, default=None,
                        help="build the log at PATH and keep it (reused when it is already "
                             "large enough; startup.py --db PATH reads it)")
    parser.add_argument("--postgresql", action="store_true",
                        help="also measure the rebuild of the same log on PostgreSQL")
    parser.add_argument("--rounds", type=int, default=None,
                        help="alternating rounds of the baseline and the rebuild, median kept "
                             "(default 3, --quick 1)")
    args = parser.parse_args()
    reports = args.reports or (100_000 if args.quick else 1_000_000)
    rounds = max(1, args.rounds or (1 if args.quick else 3))
    header(f"rebuild: replay of a {reports:,}-report log over {args.codes:,} codes")
    if args.keep is not None:
        db = args.keep.resolve()
        db.parent.mkdir(parents=True, exist_ok=True)
        ensure_log(db, reports, args.codes, args.threads)
        measure(db, rounds)
        if args.postgresql:
            measure_postgresql(db, rounds)
        print(f"   kept {db} (delete it when done: rm {db}*)")
        return
    SCRATCH.mkdir(parents=True, exist_ok=True)
    with scratch_dir("rebuild-") as workdir:
        db = workdir / "log.db"
        build_log(db, reports, args.codes, args.threads)
        measure(db, rounds)
        if args.postgresql:
            measure_postgresql(db, rounds)


if __name__ == "__main__":
    main()
