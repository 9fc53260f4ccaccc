"""FaultLedger.stats over 30 days × 3 shifts × 5,000 codes and 1,000,000 events, next to a
plain SQL GROUP BY over the raw log in the same run (issue 5 targets: ≤ 0.25×, ≤ 300 ms)."""

from __future__ import annotations

import argparse
import random
import sqlite3
import statistics
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from _common import SCRATCH, header, ratio, remove_db, url_for, verdict
from faultledger import FaultLedger, Policy, ReportRequest

TARGET_RATIO = 0.25
TARGET_MS = 300.0
START = datetime(2026, 10, 1, tzinfo=UTC)
BATCH = 4096


def build(db: Path, events: int, n_codes: int, days: int, seed: int) -> None:
    """Reports through the public API in large batches, times spread over ``days``.

    Code popularity is Zipf-like (a few bad actors, a long tail) and each report is FAILED
    or PASSED with equal odds, so faults confirm, heal and chatter as on a real line.
    """
    rng = random.Random(seed)
    names = [f"LINE{i % 7}_DEV{i:04d}_FAULT" for i in range(n_codes)]
    weights = [1.0 / (rank + 1) ** 0.8 for rank in range(n_codes)]
    span_s = days * 86_400
    stamps = sorted(rng.uniform(0, span_s) for _ in range(events))
    picks = rng.choices(range(n_codes), weights, k=events)
    policy = Policy(confirmation_threshold=-2, healing_enabled=True, healing_threshold=2)
    ledger = FaultLedger.open(url_for(db), policy=policy, max_batch=BATCH, background=False)
    started = time.perf_counter()
    seen: set[int] = set()
    try:
        for first in range(0, events, BATCH):
            batch = []
            for k in range(first, min(events, first + BATCH)):
                code = picks[k]
                kind = "FAILED" if code not in seen or rng.random() < 0.5 else "PASSED"
                seen.add(code)
                batch.append(ReportRequest(names[code], kind, rng.choice((1, 1, 2, 3)), "",
                                           f"/line{code % 7}/dev{code % 50}",
                                           START + timedelta(seconds=stamps[k])))
            results = ledger.report_many(batch)
            if not all(r.accepted for r in results):
                raise SystemExit("a report was rejected while building the log")
            if first % (BATCH * 40) == 0:
                print(f"   {first + len(batch):,} reports "
                      f"({time.perf_counter() - started:.0f} s)", flush=True)
        print(f"   built {ledger.last_seq:,} records in {time.perf_counter() - started:.0f} s")
    finally:
        ledger.close()


def ensure(db: Path, events: int, n_codes: int, days: int, seed: int) -> None:
    if db.exists():
        conn = sqlite3.connect(db)
        try:
            have = conn.execute("SELECT count(*) FROM events").fetchone()[0]
        except sqlite3.Error:
            have = 0
        conn.close()
        if have >= events:
            print(f"   reusing {db} ({have:,} records)")
            return
    remove_db(db)
    print(f"   building {events:,} reports over {n_codes:,} codes and {days} days in {db}")
    build(db, events, n_codes, days, seed)


def best_of(fn: Callable[[], Any], rounds: int) -> tuple[float, Any]:
    """Median wall time in ms (after one warm-up call) and the last result."""
    value = fn()
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        value = fn()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times), value


def plain_group_by(db: Path, since_ns: int, until_ns: int) -> Callable[[], list[Any]]:
    """The straightforward query: FAILED/PASSED reports per 8-hour shift from the raw log."""
    shift_ns = 8 * 3600 * 1_000_000_000
    sql = ("SELECT (occurred_at_ns - ?) / ? AS shift, json_extract(payload, '$.event_type'), "
           "count(*) FROM events WHERE kind = 'fault_reported' AND occurred_at_ns >= ? "
           "AND occurred_at_ns < ? GROUP BY 1, 2")

    def run() -> list[Any]:
        conn = sqlite3.connect(db)
        try:
            return conn.execute(sql, (since_ns - 6 * 3600 * 10**9, shift_ns, since_ns,
                                      until_ns)).fetchall()
        finally:
            conn.close()
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--events", type=int, default=1_000_000)
    parser.add_argument("--codes", type=int, default=5_000)
    parser.add_argument("--days", type=int, default=30)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--db", type=Path, default=SCRATCH / "stats-1M.db")
    args = parser.parse_args()
    header(f"stats over {args.days} days, {args.codes:,} codes, {args.events:,} events")
    args.db.parent.mkdir(parents=True, exist_ok=True)
    ensure(args.db, args.events, args.codes, args.days, seed=5)

    since = START.replace(hour=6)
    until = since + timedelta(days=args.days) - timedelta(hours=6)
    as_of = START + timedelta(days=args.days + 1)
    to_ns = int(since.timestamp()) * 10**9, int(until.timestamp()) * 10**9
    base_ms, base = best_of(plain_group_by(args.db, *to_ns), args.rounds)
    ledger = FaultLedger.open(url_for(args.db), background=False)
    try:
        cases: list[tuple[str, Callable[[], Any]]] = [
            ("by shift, all codes", lambda: ledger.stats("shift", since, until, as_of=as_of)),
            ("by day, all codes", lambda: ledger.stats("day", since, until, as_of=as_of)),
            ("by hour, all codes", lambda: ledger.stats("hour", since, until, as_of=as_of)),
            ("by shift, --code LINE3_DEV00*", lambda: ledger.stats(
                "shift", since, until, codes=["LINE3_DEV00*"], as_of=as_of)),
            ("by shift, group by severity", lambda: ledger.stats(
                "shift", since, until, group_by=["severity"], as_of=as_of)),
        ]
        print(f"   plain SQL GROUP BY over the raw log (failed/passed per shift): "
              f"{base_ms:.0f} ms, {len(base)} groups")
        headline = None
        for name, fn in cases:
            ms, rows = best_of(fn, args.rounds)
            print(f"   stats {name:<32} {ms:8.1f} ms  {len(rows):>5} rows  "
                  f"{ratio(ms, base_ms):5.2f}× plain")
            if headline is None:
                headline = (ms, rows)
        assert headline is not None
        ms, rows = headline
        reports = sum(r.failed_reports + r.passed_reports for r in rows)
        plain_reports = sum(count for _, _, count in base)
        if reports != plain_reports:
            raise SystemExit(f"stats counted {reports} reports, the plain query {plain_reports}")
        print(f"   both count {reports:,} reports in the range")
        print(f"   target ≤ {TARGET_RATIO}× plain: {ratio(ms, base_ms):.2f}× "
              f"{verdict(ratio(ms, base_ms) <= TARGET_RATIO)}; "
              f"target ≤ {TARGET_MS:.0f} ms: {ms:.0f} ms {verdict(ms <= TARGET_MS)}")
    finally:
        ledger.close()


if __name__ == "__main__":
    main()
