"""Durable ingest of FaultLedger.report vs raw sqlite3 fsync-per-row and eventsourcing 9.5.6."""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import shutil
import sqlite3
import statistics
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from _common import (
    BENCH_DIR,
    header,
    percentile,
    plan,
    ratio,
    report_concurrently,
    scratch_dir,
    url_for,
    verdict,
)
from faultledger import FaultLedger, Policy, ReportRequest

ES_VERSION = "9.5.6"
ES_VENV = BENCH_DIR / ".venv-eventsourcing"

Plan = list[tuple[str, str, str]]


@dataclass(frozen=True)
class Usage:
    """getrusage of this process over a run: where its CPU went and how often it switched."""

    user: float
    system: float
    voluntary: int
    involuntary: int


def usage_since(start: Usage | None = None) -> Usage:
    now = resource.getrusage(resource.RUSAGE_SELF)
    if start is None:
        return Usage(now.ru_utime, now.ru_stime, now.ru_nvcsw, now.ru_nivcsw)
    return Usage(now.ru_utime - start.user, now.ru_stime - start.system,
                 now.ru_nvcsw - start.voluntary, now.ru_nivcsw - start.involuntary)


@dataclass(frozen=True)
class Run:
    name: str
    reports: int
    records: int
    seconds: float
    commits: int
    latencies: list[float]
    cpu_seconds: float = 0.0
    usage: Usage | None = None

    @property
    def rate(self) -> float:
        return self.reports / self.seconds

    def latency_line(self) -> str:
        if not self.latencies:
            return ""
        return (f"latency per report: mean {statistics.fmean(self.latencies) * 1e3:.2f} ms, "
                f"p50 {percentile(self.latencies, 0.5) * 1e3:.2f} ms, "
                f"p99 {percentile(self.latencies, 0.99) * 1e3:.2f} ms")


# -- FaultLedger ----------------------------------------------------------------------------------
Sender = Callable[[FaultLedger], tuple[float, list[float]]]
"""Sends the plan's reports to a ledger; the seconds it took and the latencies per call."""


def measure_ledger(name: str, reports: int, db: Path, send: Sender, fsync: bool = True) -> Run:
    """One configuration on a fresh ledger: ``send`` timed, with the records, commits and CPU
    it caused. ``fsync=False``: the writer's connection at synchronous=OFF, so nothing waits
    for the disk and the process CPU is faultledger's and SQLite's work alone (never a
    setting of faultledger's: it measures what a report costs besides its fsync)."""
    ledger = FaultLedger.open(url_for(db), policy=Policy())
    try:
        # Warm-up outside the timing: records the policy, compiles the SQLAlchemy statements.
        ledger.report("BENCH_WARMUP", "FAILED", severity=2, source_id="/bench/warmup")
        if not fsync:
            ledger._writer._connection._driver.execute("PRAGMA synchronous = OFF")
        seq0, commits0 = ledger.last_seq, ledger._writer.commits
        cpu0, used0 = time.process_time(), usage_since()
        seconds, latencies = send(ledger)
        cpu, used = time.process_time() - cpu0, usage_since(used0)
        return Run(name if fsync else f"{name}, fsync off", reports, ledger.last_seq - seq0,
                   seconds, ledger._writer.commits - commits0, latencies, cpu, used)
    finally:
        ledger.close()


def run_ledger(work: Plan, threads: int, db: Path, fsync: bool = True) -> Run:
    """``threads`` synchronous callers, each reporting one at a time."""
    def send(ledger: FaultLedger) -> tuple[float, list[float]]:
        seconds, rejected, latencies = report_concurrently(ledger, work, threads)
        if rejected:
            raise SystemExit(f"{rejected} reports were rejected")
        return seconds, latencies

    name = f"FaultLedger, {threads} thread{'s' if threads > 1 else ''}"
    return measure_ledger(name, len(work), db, send, fsync)


def run_bursts(work: Plan, burst: int, db: Path) -> Run:
    """One caller sending the reports in bursts of ``burst`` through ``report_many``: the
    records per commit of ``burst`` synchronous threads, without a thread per report (the
    ROS node and the HTTP API take the requests queued behind one this way)."""
    requests = [ReportRequest(code, kind, 2, "bench", source) for code, kind, source in work]

    def send(ledger: FaultLedger) -> tuple[float, list[float]]:
        latencies: list[float] = []
        start = time.perf_counter()
        for first in range(0, len(requests), burst):
            t0 = time.perf_counter()
            results = ledger.report_many(requests[first:first + burst])
            latencies.append(time.perf_counter() - t0)
            if not all(result.accepted for result in results):
                raise SystemExit("a report was rejected")
        return time.perf_counter() - start, latencies

    return measure_ledger(f"FaultLedger, 1 caller, bursts of {burst}", len(work), db, send)


# -- (a) raw sqlite3, one commit per row ---------------------------------------------------------
RAW_SCHEMA = """
CREATE TABLE events (
    seq INTEGER PRIMARY KEY,
    event_id TEXT NOT NULL UNIQUE,
    kind TEXT NOT NULL,
    fault_code TEXT,
    source_id TEXT,
    payload TEXT NOT NULL,
    occurred_at_ns INTEGER NOT NULL,
    recorded_at_ns INTEGER NOT NULL,
    hash TEXT NOT NULL
)
"""


RAW_INSERT = ("INSERT INTO events (seq, event_id, kind, fault_code, source_id, payload, "
              "occurred_at_ns, recorded_at_ns, hash) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)")
LOG_SCHEMA = RAW_SCHEMA.replace("event_id TEXT NOT NULL UNIQUE", "event_id TEXT NOT NULL")
"""The log's own B-trees: its table alone. Its indexes by code, time and event_id are written
with the projections (``events_by_*``, Alembic 0009 and 0010), not with each record."""


def raw_row(seq: int, prev: str, code: str, kind: Any, source: str, severity: Any = 2,
            description: str = "bench") -> tuple[Any, ...]:
    """(a)'s row of one report (RAW_INSERT's parameters): the payload's JSON and a hash
    chained on ``prev``, the row before's last value."""
    payload = json.dumps({"description": description, "event_type": kind, "fault_code": code,
                          "severity": severity, "source_id": source},
                         sort_keys=True, separators=(",", ":"))
    now = time.time_ns()
    digest = hashlib.sha256(f"{prev}{seq}{payload}".encode()).hexdigest()
    return (seq, str(uuid.uuid4()), "fault_reported", code, source, payload, now, now, digest)


def run_raw(work: Plan, db: Path, log_btrees: bool = False, fsync: bool = True) -> Run:
    """(a): one INSERT and COMMIT per row into a table with the log's columns and unique
    event_id; ``log_btrees``: (a'), the same row into the log's one B-tree (no UNIQUE index),
    as faultledger's commit writes it (information; the targets use (a)).
    ``fsync=False``: synchronous=OFF, the CPU of the same work without the disk."""
    conn = sqlite3.connect(db, isolation_level=None)
    mode = conn.execute("PRAGMA journal_mode = WAL").fetchone()[0]
    conn.execute(f"PRAGMA synchronous = {'FULL' if fsync else 'OFF'}")
    sync = conn.execute("PRAGMA synchronous").fetchone()[0]
    assert mode == "wal" and sync == (2 if fsync else 0), (mode, sync)
    conn.execute(LOG_SCHEMA if log_btrees else RAW_SCHEMA)
    insert = RAW_INSERT
    # Warm-up row outside the timing (the first commit also creates the WAL file).
    conn.execute(insert, (0, "warmup", "warmup", None, None, "{}", 0, 0, "0" * 64))
    prev = "0" * 64
    latencies: list[float] = []
    cpu0 = time.process_time()
    start = time.perf_counter()
    for seq, (code, kind, source) in enumerate(work, 1):
        t0 = time.perf_counter()
        row = raw_row(seq, prev, code, kind, source)
        prev = row[-1]
        conn.execute("BEGIN IMMEDIATE")
        conn.execute(insert, row)
        conn.execute("COMMIT")
        latencies.append(time.perf_counter() - t0)
    seconds = time.perf_counter() - start
    cpu = time.process_time() - cpu0
    conn.close()
    name = ("(a') raw sqlite3, the log's one B-tree" if log_btrees
            else "(a) raw sqlite3, commit per row")
    return Run(name if fsync else f"{name}, fsync off", len(work), len(work), seconds,
               len(work), latencies, cpu)


# -- (b) eventsourcing in its own venv -----------------------------------------------------------
ES_CHILD = r'''
import json, os, sqlite3, sys, time
plan_file, db = sys.argv[1], sys.argv[2]
os.environ["PERSISTENCE_MODULE"] = "eventsourcing.sqlite"
os.environ["SQLITE_DBNAME"] = db
import eventsourcing
from eventsourcing.application import Application
from eventsourcing.domain import Aggregate, event


class Fault(Aggregate):
    @event("Created")
    def __init__(self, code: str, kind: str, severity: int, source: str) -> None:
        self.code = code
        self.reports = 1

    @event("Reported")
    def report(self, kind: str, severity: int, source: str) -> None:
        self.reports += 1


work = json.load(open(plan_file))
app = Application()
with app.recorder.datastore.get_connection(commit=False) as conn:  # what its pool configured
    raw = conn._sqlite_conn
    journal = raw.execute("PRAGMA journal_mode").fetchone()[0]
    synchronous = raw.execute("PRAGMA synchronous").fetchone()[0]
warm = Fault("BENCH_WARMUP", "FAILED", 2, "/bench/warmup")
app.save(warm)
faults = {}
latencies = []
start = time.perf_counter()
for code, kind, source in work:
    t0 = time.perf_counter()
    fault = faults.get(code)
    if fault is None:
        fault = faults[code] = Fault(code, kind, 2, source)
    else:
        fault.report(kind, 2, source)
    app.save(fault)  # one event, one transaction, one commit
    latencies.append(time.perf_counter() - t0)
seconds = time.perf_counter() - start
stored = sqlite3.connect(db).execute("SELECT count(*) FROM stored_events").fetchone()[0]
app.close()
print(json.dumps({"version": eventsourcing.__version__ if hasattr(eventsourcing, "__version__")
                  else "?", "seconds": seconds, "reports": len(work), "stored": stored - 1,
                  "journal_mode": journal, "synchronous": synchronous,
                  "latencies": latencies}))
'''


def es_python() -> Path:
    """The eventsourcing venv's interpreter, created with ``python3 -m venv`` when missing."""
    python = ES_VENV / "bin" / "python"
    check = [str(python), "-c", "import importlib.metadata as m; print(m.version('eventsourcing'))"]
    if python.exists():
        found = subprocess.run(check, capture_output=True, text=True, check=False)
        if found.stdout.strip() == ES_VERSION:
            return python
    print(f"   creating {ES_VENV} with eventsourcing=={ES_VERSION} ...", flush=True)
    subprocess.run(["python3", "-m", "venv", str(ES_VENV)], check=True)
    subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                    f"eventsourcing=={ES_VERSION}"], check=True)
    return python


def run_eventsourcing(work: Plan, workdir: Path) -> tuple[Run, dict[str, Any]]:
    python = es_python()
    plan_file = workdir / "plan.json"
    plan_file.write_text(json.dumps(work))
    child = workdir / "es_child.py"
    child.write_text(ES_CHILD)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    done = subprocess.run([str(python), str(child), str(plan_file), str(workdir / "es.db")],
                          capture_output=True, text=True, check=False, env=env, cwd=workdir)
    if done.returncode != 0:
        raise SystemExit(f"eventsourcing child failed:\n{done.stderr}")
    out: dict[str, Any] = json.loads(done.stdout)
    run = Run(f"(b) eventsourcing {ES_VERSION}, save per report", int(out["reports"]),
              int(out["stored"]), float(out["seconds"]), int(out["reports"]),
              [float(x) for x in out["latencies"]])
    return run, out


# -- why the misses --------------------------------------------------------------------------------
def cpu_us(run: Run) -> float:
    return run.cpu_seconds / run.reports * 1e6


def explain(raw: Run, many: Run, burst: Run, off: dict[str, Run], threads: int) -> None:
    """What the targets leave for faultledger's work, against what that work costs: both
    measured in this run (docs/performance.md, "Where issue 20 stands")."""
    raw_cpu, indexed_cpu = cpu_us(off["a"]), cpu_us(off["a'"])
    one_cpu, many_cpu = cpu_us(off["1"]), cpu_us(off["n"])
    budget = 1e6 / (0.8 * raw.rate) - 1e6 / raw.rate
    print()
    print(f"   1 thread: 0.8x of (a) leaves {budget:.0f} µs per report for all faultledger "
          f"does beyond raw sqlite3; that costs {one_cpu - raw_cpu:.0f} µs of CPU with fsync "
          f"off ({one_cpu:.0f} - {raw_cpu:.0f}); raw sqlite3 writing the log's one B-tree "
          f"instead of (a)'s two: {indexed_cpu - raw_cpu:+.0f} µs")
    print(f"   {threads} threads, fsync off: {off['n'].rate:,.0f}/s at {many_cpu:.0f} µs CPU "
          "per report: what the same code reaches with no wait for the disk at all")
    print(f"   {threads} threads against 1 caller sending bursts of {threads} (the same records "
          f"per commit, {burst.records / burst.commits:.1f}): {many.rate:,.0f} against "
          f"{burst.rate:,.0f}/s, {cpu_us(many):.0f} against {cpu_us(burst):.0f} µs CPU per "
          f"report; the {cpu_us(many) - cpu_us(burst):.0f} µs between are what {threads} "
          "synchronous threads cost (each sleeps until its commit is durable and is woken "
          "by the caller answered before it: the context switches above)")
    print(f"   bursts of {threads} from 1 caller run at {ratio(burst.rate, raw.rate):.2f}x (a): "
          f"the same records per commit without a thread per report, the ceiling of the "
          f"{threads}-thread ratio")


# -- main ----------------------------------------------------------------------------------------
def show(run: Run) -> None:
    extra = ""
    if run.commits and run.commits != run.reports:
        extra = (f", {run.commits} commits ({run.records / run.commits:.1f} records/commit, "
                 f"{run.seconds / run.commits * 1e3:.2f} ms per commit cycle)")
    print(f"   {run.name:<42} {run.rate:>9,.0f} reports/s  "
          f"({run.reports:,} reports, {run.records:,} records stored, {run.seconds:.2f} s{extra})")
    if run.latencies:
        print(f"   {'':<42} {run.latency_line()}")
    if run.cpu_seconds:
        print(f"   {'':<42} process CPU per report: {run.cpu_seconds / run.reports * 1e3:.3f} ms")
    if run.usage is not None:
        used, n = run.usage, run.reports
        print(f"   {'':<42} per report: user {used.user / n * 1e6:.0f} µs, system "
              f"{used.system / n * 1e6:.0f} µs, context switches {used.voluntary / n:.2f} "
              f"voluntary + {used.involuntary / n:.2f} involuntary")


def median_run(runs: list[Run]) -> Run:
    """The run with the median rate (the machine is shared: single runs are noisy)."""
    return sorted(runs, key=lambda r: r.rate)[len(runs) // 2]


def grown_log(log: Path, work: Plan, threads: int, rounds: int) -> None:
    """``threads`` reporters on a copy of a grown log (``bench/rebuild.py --keep``), each
    round beside raw sqlite3's (a) on a fresh file: what the per-record cost is once the
    log's B-trees are larger than the page cache, as on a robot after months."""
    with sqlite3.connect(log) as conn:
        (records,) = conn.execute("SELECT count(*) FROM events").fetchone()
    header(f"ingest on a grown log: {threads} threads, {len(work):,} reports per round on a "
           f"copy of {log} ({records:,} records), median of {rounds} round(s)")
    grown: list[Run] = []
    raws: list[Run] = []
    for r in range(rounds):
        with scratch_dir("ingest-grown-") as workdir:
            raws.append(run_raw(work, workdir / "raw.db"))
            copy = workdir / "grown.db"
            shutil.copyfile(log, copy)
            # The copy's half a gigabyte of dirty pages would be flushed during the timing
            # (and slow every fsync); the first reports after the open would read the
            # B-trees' pages from disk. Neither is the steady state measured here.
            os.sync()
            with FaultLedger.open(url_for(copy), policy=Policy()) as ledger:
                report_concurrently(ledger, work, threads)
            os.sync()
            grown.append(run_ledger(work, threads, copy))
        print(f"   round {r + 1}: raw {raws[-1].rate:,.0f}/s, grown log {grown[-1].rate:,.0f}/s, "
              f"{cpu_us(grown[-1]):.1f} µs CPU per report", flush=True)
    raw, many = median_run(raws), median_run(grown)
    show(raw)
    show(many)
    print(f"   {f'{threads} threads on the grown log vs (a)':<42} "
          f"{ratio(many.rate, raw.rate):>9.2f}x   (information: the targets are above)")
    print(f"   {f'{threads} threads on the grown log (reports/s)':<42} {many.rate:>10,.0f}   "
          f"target {'>= 10,000':<10} {verdict(many.rate >= 10_000)}")
    print(f"   {f'{threads} threads CPU per report (µs)':<42} {cpu_us(many):>10,.0f}   target "
          f"{'<= 100':<10} {verdict(cpu_us(many) <= 100)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true",
                        help="small sizes (500 reports, one round)")
    parser.add_argument("--reports", type=int, default=None,
                        help="reports per configuration (default 3000, --quick 500)")
    parser.add_argument("--codes", type=int, default=200)
    parser.add_argument("--threads", type=int, default=8)
    parser.add_argument("--rounds", type=int, default=None,
                        help="rounds of every configuration, median kept (default 3, --quick 1)")
    parser.add_argument("--grown", type=Path, default=None, metavar="LOG",
                        help="only the 8-thread ingest on a copy of this grown log "
                             "(bench/rebuild.py --keep var/bench/rebuild.db makes one)")
    args = parser.parse_args()
    n = args.reports or (500 if args.quick else 3000)
    rounds = args.rounds or (1 if args.quick else 3)
    work = plan(n, args.codes)
    if args.grown is not None:
        grown_log(args.grown, work, args.threads, rounds)
        return
    header(f"ingest: {n:,} reports over {args.codes} codes per configuration, median of "
           f"{rounds} round(s) (WAL, synchronous=FULL: every acknowledged report is fsynced)")

    raws: list[Run] = []
    indexed: list[Run] = []
    ess: list[Run] = []
    ones: list[Run] = []
    manys: list[Run] = []
    bursts: list[Run] = []
    cpu_only: dict[str, list[Run]] = {"a": [], "a'": [], "1": [], "n": []}
    es_info: dict[str, Any] = {}
    for r in range(rounds):
        # Interleaved rounds: a burst of load from other users hits every configuration alike.
        with scratch_dir("ingest-") as workdir:
            raws.append(run_raw(work, workdir / "raw.db"))
            indexed.append(run_raw(work, workdir / "raw-indexed.db", log_btrees=True))
            es, es_info = run_eventsourcing(work, workdir)
            ess.append(es)
            ones.append(run_ledger(work, 1, workdir / "ledger1.db"))
            manys.append(run_ledger(work, args.threads, workdir / "ledgerN.db"))
            bursts.append(run_bursts(work, args.threads, workdir / "ledgerB.db"))
            # The same work with nothing waiting for the disk: what it costs besides fsync.
            cpu_only["a"].append(run_raw(work, workdir / "raw-off.db", fsync=False))
            cpu_only["a'"].append(run_raw(work, workdir / "raw-indexed-off.db",
                                          log_btrees=True, fsync=False))
            cpu_only["1"].append(run_ledger(work, 1, workdir / "ledger1-off.db", fsync=False))
            cpu_only["n"].append(run_ledger(work, args.threads, workdir / "ledgerN-off.db",
                                            fsync=False))
        print(f"   round {r + 1}: " + ", ".join(
            f"{x[-1].rate:,.0f}/s" for x in (raws, indexed, ess, ones, manys)), flush=True)
    raw, es, one, many = (median_run(x) for x in (raws, ess, ones, manys))
    raw_indexed = median_run(indexed)
    burst = median_run(bursts)
    print()
    for run in (raw, raw_indexed, es):
        show(run)
    print(f"   {'':<42} eventsourcing's SQLite pool: journal_mode={es_info['journal_mode']}, "
          f"synchronous={es_info['synchronous']} (2 = FULL; it sets WAL itself and leaves "
          "synchronous at the build default)")
    for run in (one, many, burst):
        show(run)

    fsync_ms = statistics.median(raw.latencies) * 1e3
    cycle_ms = many.seconds / many.commits * 1e3
    print()
    print(f"   commit latency, raw sqlite3 (fsync'd WAL commit of one row): median {fsync_ms:.2f} "
          f"ms, mean {statistics.fmean(raw.latencies) * 1e3:.2f} ms")
    print(f"   {args.threads} threads: {many.records / many.commits:.1f} records per group commit,"
          f" one commit every {cycle_ms:.2f} ms; with {args.threads} synchronous callers at most "
          f"{args.threads} reports share a commit, so the rate is <= {args.threads} / cycle")
    print(f"   {'':<11}bound if a cycle cost only the fsync: {args.threads} / {fsync_ms:.2f} ms = "
          f"{args.threads / fsync_ms * 1e3:,.0f} reports/s; the rest of the cycle is Python CPU "
          f"({many.cpu_seconds / many.reports * 1e3:.3f} ms CPU per report on 2 cores)")
    off = {key: median_run(runs) for key, runs in cpu_only.items()}
    print()
    print("   the same work with synchronous=OFF (nothing waits for the disk: CPU alone):")
    for run in off.values():
        print(f"   {run.name:<50} {run.rate:>9,.0f}/s  "
              f"{run.cpu_seconds / run.reports * 1e6:>6.1f} µs CPU per report")
    explain(raw, many, burst, off, args.threads)
    print()
    per_report = cpu_us(many)
    checks = [  # issue 20's targets
        ("1 thread vs (a) raw sqlite3", ratio(one.rate, raw.rate), 0.8, False),
        ("1 thread vs (b) eventsourcing", ratio(one.rate, es.rate), 1.5, False),
        (f"{args.threads} threads vs (a) raw sqlite3", ratio(many.rate, raw.rate), 2.0, False),
        (f"{args.threads} threads absolute (reports/s)", many.rate, 10_000.0, True),
    ]
    label = "1 thread vs (a') the log's one B-tree"
    print(f"   {label:<42} {ratio(one.rate, raw_indexed.rate):>9.2f}x   (information)")
    for name, value, target, absolute in checks:
        shown = f"{value:,.0f}" if absolute else f"{value:.2f}x"
        goal = f">= {target:,.0f}" if absolute else f">= {target:.1f}x"
        print(f"   {name:<42} {shown:>10}   target {goal:<10} {verdict(value >= target)}")
    print(f"   {f'{args.threads} threads CPU per report (µs)':<42} {per_report:>10,.0f}   target "
          f"{'<= 100':<10} {verdict(per_report <= 100)}")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
