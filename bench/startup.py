"""Startup time of FaultLedger.open on a large log, and memory held per active fault."""

from __future__ import annotations

import argparse
import gc
import sqlite3
import statistics
import threading
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

from _common import codes, header, ratio, scratch_dir, url_for, verdict
from faultledger import FaultLedger, Policy
from rebuild import build_log, count_events

TARGET_OPEN_S = 1.0


def median_time(fn: Callable[[], object], times: int) -> float:
    samples = []
    for _ in range(times):
        start = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples)


def open_close(url: str) -> None:
    FaultLedger.open(url).close()


def count_rows(db: Path) -> None:
    conn = sqlite3.connect(db)
    conn.execute("SELECT count(*) FROM events").fetchone()
    conn.close()


def measure_startup(db: Path, times: int) -> None:
    url = url_for(db)
    events = count_events(db)
    ledger = FaultLedger.open(url)
    restored = ledger.restored
    ledger.close()
    open_close(url)  # warm the page cache and the imports
    count_rows(db)
    base = median_time(lambda: count_rows(db), times)
    opened = median_time(lambda: open_close(url), times)
    serving = median_time(lambda: FaultLedger.open(url, policy=Policy()).close(), times)
    print(f"   log: {events:,} records; restored: events={restored.events:,} "
          f"faults={restored.faults:,} replayed={restored.replayed:,}")
    print(f"   baseline: sqlite3.connect + SELECT count(*)     {base * 1e3:>9.1f} ms")
    print(f"   FaultLedger.open(url) + close()                 {opened * 1e3:>9.1f} ms  "
          f"({ratio(opened, base):,.0f}x baseline)   target <= {TARGET_OPEN_S:.0f} s  "
          f"{verdict(opened <= TARGET_OPEN_S)}")
    print(f"   FaultLedger.open(url, policy=Policy()) + close() {serving * 1e3:>8.1f} ms  "
          "(serving writer: timer thread; writes nothing when the policy is unchanged)")


def traced_delta(make: Callable[[], Any]) -> tuple[Any, int]:
    """Bytes still allocated (tracemalloc) after ``make()``, the object kept alive."""
    gc.collect()
    before = tracemalloc.get_traced_memory()[0]
    obj = make()
    gc.collect()
    return obj, tracemalloc.get_traced_memory()[0] - before


def fill_faults(ledger: FaultLedger, names: list[str], threads: int = 32) -> None:
    shares = [names[t::threads] for t in range(threads)]

    def worker(share: list[str]) -> None:
        for code in share:
            if not ledger.report(code, "FAILED", severity=2, description="memory bench",
                                 source_id="/bench/memory").accepted:
                raise RuntimeError(f"report of {code} rejected")

    pool = [threading.Thread(target=worker, args=(s,)) for s in shares]
    for thread in pool:
        thread.start()
    for thread in pool:
        thread.join()


def measure_memory(workdir: Path, n_faults: int) -> None:
    names = codes(n_faults)
    empty_db, full_db = workdir / "empty.db", workdir / "faults.db"
    FaultLedger.open(url_for(empty_db), policy=Policy()).close()

    tracemalloc.start()
    open_close(url_for(empty_db))  # warm-up: module-level caches are not the ledger's state

    # Live: a serving ledger on a fresh DB, then n FAILED reports of distinct codes.
    live, live_base = traced_delta(lambda: FaultLedger.open(url_for(full_db), policy=Policy()))
    gc.collect()
    before_fill = tracemalloc.get_traced_memory()[0]
    start = time.perf_counter()
    fill_faults(live, names)
    fill_s = time.perf_counter() - start
    gc.collect()
    live_state = tracemalloc.get_traced_memory()[0] - before_fill
    active = len(live.list_faults())
    live.close()
    del live

    # Restored: open the same DB again; the state is what open loads minus an empty open.
    empty, empty_bytes = traced_delta(lambda: FaultLedger.open(url_for(empty_db)))
    empty.close()
    del empty
    restored, full_bytes = traced_delta(lambda: FaultLedger.open(url_for(full_db)))
    restored_faults = restored.restored.faults
    restored.close()
    del restored

    # Baseline: the same fault rows as plain sqlite3 tuples held in a list.
    def raw_rows() -> list[Any]:
        conn = sqlite3.connect(full_db)
        rows = conn.execute("SELECT * FROM faults").fetchall()
        conn.close()
        return rows

    rows, raw_bytes = traced_delta(raw_rows)
    tracemalloc.stop()

    restored_state = full_bytes - empty_bytes
    print(f"   {n_faults:,} distinct codes reported FAILED in {fill_s:.1f} s; "
          f"{active:,} active faults live, {restored_faults:,} restored")
    print(f"   baseline: the {len(rows):,} fault rows as sqlite3 tuples   "
          f"{raw_bytes / 1e6:>7.2f} MB  {raw_bytes / len(rows):>6,.0f} B/fault")
    print(f"   ledger state, restored by open (open minus empty open) {restored_state / 1e6:>7.2f}"
          f" MB  {restored_state / n_faults:>6,.0f} B/fault  "
          f"({ratio(restored_state, raw_bytes):.1f}x baseline)")
    print(f"   ledger state, live after the reports (growth)          {live_state / 1e6:>7.2f}"
          f" MB  {live_state / n_faults:>6,.0f} B/fault  "
          f"({ratio(live_state, raw_bytes):.1f}x baseline)")
    print(f"   (an open ledger itself, empty DB: {empty_bytes / 1e6:.2f} MB; "
          f"first open of a fresh DB: {live_base / 1e6:.2f} MB)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true",
                        help="100,000-report log and 2,000 faults when no --db is given")
    parser.add_argument("--db", type=Path, default=None,
                        help="reuse a log built by `rebuild.py --keep PATH` (left in place)")
    parser.add_argument("--reports", type=int, default=None,
                        help="size of the log built when no --db (default 1,000,000)")
    parser.add_argument("--faults", type=int, default=None,
                        help="active faults for the memory figure (default 10,000)")
    parser.add_argument("--times", type=int, default=5, help="repetitions (median kept)")
    args = parser.parse_args()
    n_faults = args.faults or (2_000 if args.quick else 10_000)
    header("startup: FaultLedger.open + close on a large log; memory per active fault")
    with scratch_dir("startup-") as workdir:
        if args.db is not None:
            db = args.db.resolve()
            if not db.exists():
                raise SystemExit(f"{db} does not exist: run bench/rebuild.py --keep {db}")
        else:
            reports = args.reports or (100_000 if args.quick else 1_000_000)
            db = workdir / "log.db"
            print(f"   building a log of {reports:,} reports (use --db to reuse one) ...",
                  flush=True)
            build_log(db, reports, 5000, 48)
        measure_startup(db, args.times)
        print()
        measure_memory(workdir, n_faults)


if __name__ == "__main__":
    main()
