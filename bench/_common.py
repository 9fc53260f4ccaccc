"""Shared helpers of the benchmark scripts: scratch directories on the real disk, verdicts."""

from __future__ import annotations

import contextlib
import os
import platform
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TypeVar

from faultledger import FaultLedger

BENCH_DIR = Path(__file__).resolve().parent
ROOT = BENCH_DIR.parent
SCRATCH = ROOT / "var" / "bench"
"""Scratch space on the same disk as a real deployment (not /tmp, which may be tmpfs)."""

T = TypeVar("T")


@contextlib.contextmanager
def scratch_dir(prefix: str) -> Iterator[Path]:
    """A fresh directory under var/bench, removed with everything in it afterwards."""
    SCRATCH.mkdir(parents=True, exist_ok=True)
    path = Path(tempfile.mkdtemp(prefix=prefix, dir=SCRATCH))
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


def url_for(path: Path) -> str:
    return f"sqlite:///{path.resolve()}"


def remove_db(path: Path) -> None:
    """Delete an SQLite file and its WAL/SHM companions."""
    for suffix in ("", "-wal", "-shm", "-journal"):
        Path(f"{path}{suffix}").unlink(missing_ok=True)


def machine() -> str:
    return (f"{os.cpu_count()} cores, Python {platform.python_version()}, "
            f"SQLite {sqlite3.sqlite_version}, {platform.platform()}")


def verdict(ok: bool) -> str:
    return "PASS" if ok else "MISS"


def ratio(a: float, b: float) -> float:
    return a / b if b else float("inf")


def timed(fn: Callable[[], T]) -> tuple[T, float]:
    start = time.perf_counter()
    value = fn()
    return value, time.perf_counter() - start


def codes(count: int) -> list[str]:
    return [f"BENCH_FAULT_{i:05d}" for i in range(count)]


def plan(n: int, n_codes: int, failed_share: float = 0.6) -> list[tuple[str, str, str]]:
    """``n`` (code, FAILED|PASSED, source) triples; the first report of every code is FAILED.

    Deterministic (no RNG state shared with anything): a PASSED for a code that has no fault
    yet would be accepted without storing a record, which would flatter the figures.
    """
    names = codes(n_codes)
    out: list[tuple[str, str, str]] = []
    for i in range(n):
        code = names[i % n_codes]
        # Knuth's multiplicative hash spreads FAILED/PASSED evenly and reproducibly.
        failed = i < n_codes or ((i * 2654435761) % 1000) < failed_share * 1000
        out.append((code, "FAILED" if failed else "PASSED", f"/bench/src{i % 16}"))
    return out


def report_concurrently(ledger: FaultLedger, work: Sequence[tuple[str, str, str]], threads: int,
                        progress_every: int = 0) -> tuple[float, int, list[float]]:
    """Report ``work`` from ``threads`` threads (interleaved shares); returns (seconds,
    rejected count, per-call latencies in seconds)."""
    shares = [work[t::threads] for t in range(threads)]
    barrier = threading.Barrier(threads + 1)
    rejected = [0] * threads
    latencies: list[list[float]] = [[] for _ in range(threads)]
    done = [0] * threads

    def worker(t: int) -> None:
        mine = latencies[t]
        barrier.wait()
        for code, kind, source in shares[t]:
            start = time.perf_counter()
            result = ledger.report(code, kind, severity=2, description="bench",
                                   source_id=source)
            mine.append(time.perf_counter() - start)
            if not result.accepted:
                rejected[t] += 1
            done[t] += 1

    pool = [threading.Thread(target=worker, args=(t,), daemon=True) for t in range(threads)]
    for thread in pool:
        thread.start()
    barrier.wait()
    start = time.perf_counter()
    if progress_every:
        last = 0
        while any(thread.is_alive() for thread in pool):
            time.sleep(0.5)
            total = sum(done)
            if total - last >= progress_every:
                elapsed = time.perf_counter() - start
                print(f"  ... {total:,}/{len(work):,} reports, {total / elapsed:,.0f}/s",
                      flush=True)
                last = total
    for thread in pool:
        thread.join()
    elapsed = time.perf_counter() - start
    return elapsed, sum(rejected), [x for share in latencies for x in share]


def percentile(values: Sequence[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def revision() -> str:
    """The commit measured (``-dirty``: with uncommitted changes in the work tree)."""
    done = subprocess.run(["git", "-C", str(ROOT), "describe", "--always", "--dirty"],
                          capture_output=True, text=True, check=False)
    return done.stdout.strip() or "unknown"


def header(title: str) -> None:
    print(f"== {title}")
    print(f"   machine: {machine()}")
    print(f"   code:    faultledger {revision()}, {sys.executable}, {compiled_modules()}")


def compiled_modules() -> str:
    """How many of the per-record modules have compiled files beside the imported sources
    (stale ones are removed at import: docs/architecture.md)."""
    from faultledger import compiled

    running = sum(1 for name in compiled.MODULES if compiled.built(name))
    if not running:
        return "plain Python (nothing compiled)"
    return f"{running}/{len(compiled.MODULES)} per-record modules compiled (mypyc)"
