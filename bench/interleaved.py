"""One reporter's gap to raw sqlite3, with both in one process taking turns.

bench/ingest.py times raw sqlite3 (a) and faultledger one after the other. Run alone in a
loop, raw sqlite3's COMMIT is faster than in a process that does other work between its
commits: its fdatasync sleeps, and what ran meanwhile has taken the caches. Here raw sqlite3
commits alone first, then a faultledger report and a raw sqlite3 report take turns (each its
own file, both fsynced): raw sqlite3's COMMIT alone against the same COMMIT between
faultledger's reports, and the two whole reports side by side under the same conditions.
Information for issue 20 (docs/performance.md, "Thirteenth round"); no target here.
"""

from __future__ import annotations

import argparse
import sqlite3
import statistics
import time
from pathlib import Path

from _common import header, plan, remove_db, scratch_dir, url_for
from faultledger import FaultLedger, Policy
from ingest import LOG_SCHEMA, RAW_INSERT, raw_row


class RawLog:
    """(a') of bench/ingest.py: one row into the log's one B-tree, one fsync'd commit."""

    def __init__(self, db: Path) -> None:
        self.conn = sqlite3.connect(db, isolation_level=None)
        assert self.conn.execute("PRAGMA journal_mode = WAL").fetchone()[0] == "wal"
        self.conn.execute("PRAGMA synchronous = FULL")
        self.conn.execute(LOG_SCHEMA)
        self.seq = 0
        self.prev = "0" * 64
        self.commits: list[float] = []

    def report(self, code: str, kind: str, source: str) -> None:
        self.seq += 1
        row = raw_row(self.seq, self.prev, code, kind, source)
        self.prev = row[-1]
        self.conn.execute("BEGIN IMMEDIATE")
        self.conn.execute(RAW_INSERT, row)
        started = time.perf_counter()
        self.conn.execute("COMMIT")
        self.commits.append(time.perf_counter() - started)


def median_us(values: list[float]) -> float:
    return statistics.median(values) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--reports", type=int, default=8000, help="reports of each (8000)")
    args = parser.parse_args()
    header("one reporter: raw sqlite3 alone, then taking turns with faultledger")
    work = plan(args.reports, 200)
    skip = min(2000, args.reports // 4)  # the WAL of a new file grows first (twelfth round)
    with scratch_dir("interleaved-") as scratch:
        alone = RawLog(scratch / "alone.db")
        for code, kind, source in work:
            alone.report(code, kind, source)
        raw = RawLog(scratch / "raw.db")
        db = scratch / "faults.db"
        remove_db(db)
        ledger = FaultLedger.open(url_for(db), policy=Policy())
        ours: list[float] = []
        theirs: list[float] = []
        try:
            for code, kind, source in work:
                started = time.perf_counter()
                ledger.report(code, kind, 2, "bench", source)
                middle = time.perf_counter()
                raw.report(code, kind, source)
                theirs.append(time.perf_counter() - middle)
                ours.append(middle - started)
        finally:
            ledger.close()
    print(f"   {args.reports:,} reports each; medians after the first {skip:,}")
    alone_us, between_us = median_us(alone.commits[skip:]), median_us(raw.commits[skip:])
    print(f"   raw sqlite3 COMMIT, alone in its loop            {alone_us:7.1f} µs")
    print(f"   raw sqlite3 COMMIT, between faultledger reports  {between_us:7.1f} µs")
    print(f"   whole report, taking turns: raw sqlite3 {median_us(theirs[skip:]):.1f} µs, "
          f"faultledger {median_us(ours[skip:]):.1f} µs: "
          f"{statistics.median(theirs[skip:]) / statistics.median(ours[skip:]):.2f}x")


if __name__ == "__main__":
    main()
