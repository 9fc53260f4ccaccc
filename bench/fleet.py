"""Fleet ingest: robot processes pushing their logs concurrently into one central on PostgreSQL.

What it measures (docs/performance.md, "Fleet"), each against a baseline in the same run:

- **push**: ROBOTS processes, each holding a real robot log (SQLite, RECORDS records made
  through ``FaultLedger.report``), push it to a central (``faultledger http --db
  postgresql+psycopg://…``) over HTTP as ``faultledger sync`` does (its record encoding, its
  batch sizes: ``fleet/pace.py``), all at once. Each robot's first record is pushed before the
  timing (its first contact: the central makes the robot's log), and timed apart. Figures:
  records/s into the central (all records / wall time from the first push to the last
  answer), p99 of one batch's acknowledgement, CPU per record by process (/proc), and how
  soon the central answers statistics over everything pushed (its projections follow the
  pushes, docs/fleet.md). Baseline: the same rows written with one ``COPY`` per 1,000 rows
  (psycopg) into a table of the same columns in the same PostgreSQL, from the same number of
  processes: the server's raw ingest, no checks.
- **single robot**: one robot pushing alone, against raw psycopg inserts (executemany, one
  transaction per 1,000 rows) of the same rows.

- **statistics**: STATS_ROBOTS robot logs of 30 days each (made in memory with the domain's
  own hashing, imported through ``Fleet.push``), then ``stats --by shift --group-by robot``
  over the 30 days at the central. Baseline: a plain ``GROUP BY robot, shift`` count over the
  same raw records in one table of the same PostgreSQL.

Targets (issue 19): ≥ 30,000 records/s and ≥ 0.5× raw COPY, p99 batch ≤ 250 ms; statistics
over 30 days × 100 robots (5M records) ≤ 1 s and ≤ 0.25× the plain GROUP BY.

The PostgreSQL server is started here, as the tests do (tests/pg_server.py: Debian's
postgresql 15, run as the ``postgres`` user on a loopback port, data in a temporary directory).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import re
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx  # imported here, before the robot processes fork: not in their timed work
import psycopg

from _common import ROOT, header, percentile, ratio, scratch_dir, verdict

sys.path.insert(0, str(ROOT))
from datetime import timedelta

from tests import pg_server

from faultledger import FaultLedger, Policy
from faultledger.domain.clock import to_ns
from faultledger.fleet.pace import BatchPace
from faultledger.fleet.push import record_json
from faultledger.service.audit import export_history

BATCH = 1_000
"""Records per push, the most `faultledger sync` sends (docs/fleet.md)."""
READY = re.compile(r"faultledger http ready.*?: (http://[0-9.:]+/)")
COLUMNS = ("seq", "event_id", "kind", "fault_code", "source_id", "payload", "occurred_at_ns",
           "recorded_at_ns", "schema_version", "hash")


def make_robot_log(path: Path, robot_id: str, records: int) -> None:
    with FaultLedger.open(f"sqlite:///{path}", policy=Policy(), robot_id=robot_id,
                          background=False) as ledger:
        from faultledger.service.requests import ReportRequest

        done = 0
        while ledger.last_seq < records:
            burst = [ReportRequest(f"BENCH_{(done + i) % 40:02d}",
                                   "FAILED" if (done + i) % 3 else "PASSED", 1,
                                   f"bench record {done + i}", f"/{robot_id}/driver")
                     for i in range(min(500, records - ledger.last_seq))]
            ledger.report_many(burst)
            done += len(burst)


def prepare(path: Path) -> Path:
    """A robot log as ``faultledger sync`` encodes it (a first line with the identity and
    head, then one record's JSON a line), made before anything is timed."""
    with FaultLedger.open(f"sqlite:///{path}") as robot:
        identity = robot.identity
        assert identity is not None
        rows = list(export_history(robot))
    out = path.with_suffix(".records")
    with out.open("w") as lines:
        lines.write(json.dumps({"robot_id": identity.robot_id, "ledger_id": identity.ledger_id,
                                "head_seq": rows[-1].seq}) + "\n")
        for row in rows:
            lines.write(record_json(row) + "\n")
    return out


def records_in(path: str) -> tuple[bytes, list[bytes]]:
    """(the body's start up to ``"records":[``, the records' JSON) of a prepared log."""
    head, *records = Path(path).read_bytes().splitlines()
    return head[:-1] + b',"records":[', records


def body(start: bytes, records: list[bytes]) -> bytes:
    return start + b",".join(records) + b"]}"


def first_contact(url: str, prepared: list[str]) -> float:
    """Each robot's first record, pushed one robot after the other (the central makes the
    robot's log: a PostgreSQL schema through the migrations): seconds per robot."""
    started = time.perf_counter()
    with httpx.Client(base_url=url, timeout=60.0) as client:
        for path in prepared:
            start, records = records_in(path)
            client.post("/api/v1/fleet/records", content=body(start, records[:1]),
                        headers={"content-type": "application/json"}).raise_for_status()
    return (time.perf_counter() - started) / len(prepared)


Timings = list[tuple[float, float, int]]
"""(start, end, records) of every batch one robot sent, in order."""


def push_worker(url: str, path: str) -> Callable[[], Timings]:
    """Push a robot's log as ``faultledger sync`` does: batches sized by ``BatchPace``."""
    start, records = records_in(path)
    client = httpx.Client(base_url=url, timeout=60.0)
    client.get("/health").raise_for_status()

    def go() -> Timings:
        times = []
        pace, at = BatchPace(BATCH), 1  # the central holds the first record (first contact)
        try:
            while at < len(records):
                part = records[at:at + pace.size]
                began = time.time()
                answer = client.post("/api/v1/fleet/records", content=body(start, part),
                                     headers={"content-type": "application/json"})
                if answer.status_code != 200:
                    raise RuntimeError(f"push refused: {answer.status_code} "
                                       f"{answer.text[:300]}")
                done = time.time()
                pace.answered(len(part), done - began)
                times.append((began, done, answer.json()["stored"]))
                at += len(part)
        finally:
            client.close()
        return times
    return go


def batches(path: str) -> list[list[dict[str, Any]]]:
    """The prepared log's records in batches of 1,000 (the raw baselines)."""
    records = [json.loads(raw) for raw in records_in(path)[1]]
    return [records[at:at + BATCH] for at in range(0, len(records), BATCH)]


def copy_worker(dsn: str, path: str, chain: int) -> Callable[[], Timings]:
    """The same rows with one COPY per batch into a plain table (the raw baseline)."""
    parts = batches(path)
    conn = psycopg.connect(dsn)

    def go() -> Timings:
        times = []
        with conn:
            for part in parts:
                began = time.time()
                with conn.cursor() as cursor, cursor.copy(
                        "COPY raw_records (chain_id, " + ", ".join(COLUMNS)
                        + ") FROM STDIN") as copy:
                    for r in part:
                        copy.write_row((chain, *(r[c] for c in COLUMNS)))
                conn.commit()
                times.append((began, time.time(), len(part)))
        return times
    return go


def insert_worker(dsn: str, path: str) -> Timings:
    """Raw psycopg inserts (executemany, one transaction per batch) of one robot's rows."""
    times = []
    sql = ("INSERT INTO raw_records (chain_id, " + ", ".join(COLUMNS) + ") VALUES ("
           + ", ".join(["%s"] * (len(COLUMNS) + 1)) + ")")
    with psycopg.connect(dsn) as conn:
        for part in batches(path):
            began = time.time()
            with conn.cursor() as cursor:
                cursor.executemany(sql, [(999, *(r[c] for c in COLUMNS)) for r in part])
            conn.commit()
            times.append((began, time.time(), len(part)))
    return times


def _together(work: Any, barrier: Any, results: Any, index: int, *args: Any) -> None:
    try:
        go = work(*args)  # set up (load the records, connect)
    except BaseException:
        barrier.abort()
        raise
    barrier.wait()  # every process is ready: all begin at once
    cpu = time.process_time()
    try:
        results.put((index, (go(), time.process_time() - cpu)))
    except BaseException as error:
        results.put((index, error))
        raise


def all_at_once(work: Any, jobs: list[tuple[Any, ...]], done: Callable[[], Any] = lambda: None
                ) -> tuple[list[Timings], float]:
    """``work(*job)()`` in one process per job, set up first, then started together: their
    timings and the CPU seconds they used. ``done`` is called as soon as the last one has
    answered (before the processes end)."""
    barrier = multiprocessing.Barrier(len(jobs))
    results: Any = multiprocessing.Queue()
    processes = [multiprocessing.Process(target=_together, args=(work, barrier, results, n, *job))
                 for n, job in enumerate(jobs)]
    for process in processes:
        process.start()
    found = dict(results.get(timeout=600) for _ in processes)
    done()
    failed = [item for item in found.values() if isinstance(item, BaseException)]
    if failed:
        raise RuntimeError(f"{len(failed)} of {len(jobs)} processes failed") from failed[0]
    for process in processes:
        process.join(60)
    return [found[n][0] for n in range(len(jobs))], sum(cpu for _, cpu in found.values())


def projected(url: str, runs: list[list[tuple[float, float, int]]]) -> float:
    """Records/s from the first push until the central answers statistics by robot over
    every record (the answer waits for the logs' projections, docs/fleet.md)."""

    answer = httpx.get(f"{url}api/v1/stats", params={"by": "day", "group_by": "robot"},
                       timeout=600)
    answer.raise_for_status()
    done = time.time()
    first = min(s for run in runs for s, _, _ in run)
    return sum(n for run in runs for _, _, n in run) / (done - first)


def cpu_seconds(central_pid: int) -> dict[str, float]:
    """CPU seconds used so far: by the whole machine, the central, and PostgreSQL's
    processes (from /proc), to say where a push's CPU goes."""
    tick = os.sysconf("SC_CLK_TCK")
    fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:]
    busy = sum(int(v) for i, v in enumerate(fields) if i not in (3, 4)) / tick
    found = {"machine": busy, "central": 0.0, "postgresql": 0.0}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        name = stat[stat.index("(") + 1:stat.rindex(")")]
        rest = stat[stat.rindex(")") + 2:].split()
        used = (int(rest[11]) + int(rest[12])) / tick
        if int(entry.name) == central_pid:
            found["central"] += used
        elif name == "postgres":
            found["postgresql"] += used
    return found


def summary(runs: list[list[tuple[float, float, int]]]) -> tuple[float, float, int]:
    """(records/s over the wall time of all pushes, p99 batch seconds, records)."""
    spans = [item for run in runs for item in run]
    first, last = min(s for s, _, _ in spans), max(e for _, e, _ in spans)
    records = sum(n for _, _, n in spans)
    return records / (last - first), percentile([e - s for s, e, _ in spans], 0.99), records


def start_central(url: str, log: Path) -> tuple[subprocess.Popen[bytes], str]:
    out = log.open("wb")
    process = subprocess.Popen([sys.executable, "-m", "faultledger.cli.main", "http", "--db",
                                url, "--listen", "127.0.0.1:0"], stdout=out,
                               stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        found = READY.search(log.read_text(errors="replace"))
        if found:
            return process, found.group(1)
        if process.poll() is not None:
            break
        time.sleep(0.1)
    process.kill()
    raise RuntimeError("central did not start:\n" + log.read_text(errors="replace"))


def synthetic_log(robot_id: str, records: int, days: int, seed: int
                  ) -> tuple[str, list[Any]]:
    """A robot log of ``records`` records over ``days`` days, hashed as a robot would:
    identity, policy, then reports of 24 codes (e-stops among them) and goal outcomes."""
    import random
    import uuid

    from faultledger.domain.events import (
        FaultReported,
        GoalOutcome,
        LedgerIdentified,
        PolicyChanged,
        goal_event_id,
    )
    from faultledger.domain.fleet import PushedRecord
    from faultledger.domain.integrity import GENESIS_HASH, canonical_json, record_hash
    from faultledger.domain.types import EventType

    rng = random.Random(seed)
    ledger_id = str(uuid.UUID(int=rng.getrandbits(128), version=4))
    start_ns = 1_790_000_000 * 10**9
    step = days * 86_400 * 10**9 // records
    events: list[Any] = [LedgerIdentified(robot_id, ledger_id),
                         PolicyChanged(Policy().to_record())]
    codes = [f"BENCH_{n:02d}" for n in range(22)] + ["HW_BASE_EMERGENCY_STOP", "NAV_ABORT"]
    while len(events) < records:
        n = len(events)
        if rng.random() < 0.05:
            events.append(GoalOutcome("/navigate", f"{robot_id}-{n}",
                                      rng.choice(["ABORTED", "SUCCEEDED", "SUCCEEDED"]),
                                      "/bt_navigator"))
        else:
            events.append(FaultReported(rng.choice(codes), EventType.FAILED if rng.random() < 0.6
                                        else EventType.PASSED, 2, "", f"/{robot_id}/base"))
    out, prev = [], GENESIS_HASH
    for seq, event in enumerate(events, start=1):
        at = start_ns + seq * step
        event_id = (goal_event_id(event.action, event.goal_id) if isinstance(event, GoalOutcome)
                    else str(uuid.UUID(int=rng.getrandbits(128), version=4)))
        payload = canonical_json(event.payload())
        code = getattr(event, "fault_code", None)
        source = getattr(event, "source_id", None)
        if isinstance(event, LedgerIdentified | PolicyChanged):
            code = source = None
        digest = record_hash(prev, seq, event_id, event.kind, code, source, payload, at, at, 1)
        out.append(PushedRecord(seq, event_id, event.kind, code, source, payload, at, at, 1,
                                digest, prev))
        prev = digest
    return ledger_id, out


def stats_part(server: pg_server.PostgresServer, robots: int, records: int,
               open_logs: int = 32) -> None:


    from faultledger.service.fleet import Fleet, PushBatch

    url = server.database("stats")
    dsn = url.replace("postgresql+psycopg://", "postgresql://")
    with psycopg.connect(dsn, autocommit=True) as conn:
        conn.execute("CREATE TABLE raw_records (robot_id text, seq bigint, kind text, "
                     "fault_code text, payload text, occurred_at_ns bigint)")
    started = time.monotonic()
    first = None
    with FaultLedger.open(url, background=False) as central, \
            Fleet(central, open_logs=open_logs) as fleet:
        for n in range(robots):
            robot_id = f"robot-{n:03d}"
            ledger_id, log = synthetic_log(robot_id, records, 30, n)
            first = first or log[2].occurred_at_ns
            for at in range(0, len(log), 1_000):
                fleet.push(PushBatch(robot_id, ledger_id, log[-1].seq, log[at:at + 1_000]))
            with psycopg.connect(dsn) as conn, conn.cursor() as cursor, cursor.copy(
                    "COPY raw_records FROM STDIN") as copy:
                for r in log:
                    copy.write_row((robot_id, r.seq, r.kind, r.fault_code, r.payload,
                                    r.occurred_at_ns))
            if n % 10 == 9:
                print(f"  {n + 1} robots imported ({time.monotonic() - started:.0f} s)",
                      flush=True)
        with psycopg.connect(dsn, autocommit=True) as conn:
            conn.execute("VACUUM ANALYZE")  # every table, both sides: no autovacuum mid-timing
        from faultledger.domain.clock import from_ns

        since = from_ns(first or 0).replace(hour=0, minute=0, second=0, microsecond=0)
        until = since + timedelta(days=30)
        fleet.stats("shift", since, until, group_by=["robot"], as_of=until)  # every log projected
        timings = []
        for _ in range(5):
            t = time.perf_counter()
            rows = fleet.stats("shift", since, until, group_by=["robot"], as_of=until)
            timings.append(time.perf_counter() - t)
        ours = min(timings)
        plain = []
        shift_ns = 8 * 3600 * 10**9
        for _ in range(5):
            t = time.perf_counter()
            with psycopg.connect(dsn) as conn:
                conn.execute("SELECT robot_id, occurred_at_ns / %s AS shift, count(*), "
                             "count(*) FILTER (WHERE kind = 'goal_outcome') FROM raw_records "
                             "WHERE occurred_at_ns >= %s AND occurred_at_ns < %s "
                             "GROUP BY 1, 2", (shift_ns, to_ns(since), to_ns(until))
                             ).fetchall()
            plain.append(time.perf_counter() - t)
        baseline = min(plain)
    total = robots * records
    print(f"statistics by shift over 30 days, grouped by robot: {robots} robots, {total:,} "
          f"records, {len(rows):,} rows in {ours * 1e3:.0f} ms (best of 5); plain GROUP BY over "
          f"the raw records {baseline * 1e3:.0f} ms")
    print(f"  ≤ 1 s: {verdict(ours <= 1.0)}; ratio {ratio(ours, baseline):.2f}× "
          f"{verdict(ratio(ours, baseline) <= 0.25)} (target ≤ 0.25×)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=20)
    parser.add_argument("--records", type=int, default=5_000, help="records per robot log")
    parser.add_argument("--part", choices=["push", "stats", "all"], default="all")
    parser.add_argument("--stats-robots", type=int, default=100)
    parser.add_argument("--stats-records", type=int, default=50_000)
    parser.add_argument("--profile", metavar="FILE",
                        help="sample the central with py-spy during the pushes (raw stacks)")
    parser.add_argument("--open-logs", type=int, default=32,
                        help="robot logs the central keeps open (Fleet open_logs)")
    args = parser.parse_args()
    if args.part == "stats":
        header(f"fleet statistics: {args.stats_robots} robots × {args.stats_records:,} records")
        with pg_server.running() as server:
            stats_part(server, args.stats_robots, args.stats_records, args.open_logs)
        return 0
    header(f"fleet push: {args.robots} robots × {args.records:,} records into a PostgreSQL "
           "central")
    with scratch_dir("fleet") as scratch, pg_server.running() as server:
        started = time.monotonic()
        paths = [scratch / f"robot-{n:02d}.db" for n in range(args.robots + 1)]
        with multiprocessing.Pool(2) as pool:
            pool.starmap(make_robot_log, [(p, f"robot-{n:02d}", args.records)
                                          for n, p in enumerate(paths)])
        print(f"robot logs made in {time.monotonic() - started:.1f} s", flush=True)

        raw_url = server.empty_database("raw")
        dsn = raw_url.replace("postgresql+psycopg://", "postgresql://")


        with psycopg.connect(dsn, autocommit=True) as conn:
            conn.execute("CREATE TABLE raw_records (chain_id integer, seq bigint, "
                         "event_id varchar(36), kind varchar(40), fault_code varchar(128), "
                         "source_id text, payload text, occurred_at_ns bigint, "
                         "recorded_at_ns bigint, schema_version integer, hash varchar(64), "
                         "PRIMARY KEY (chain_id, seq))")
        with multiprocessing.Pool(2) as pool:
            prepared = [str(p) for p in pool.map(prepare, paths)]
        robots = prepared[:args.robots]
        copy_runs, _ = all_at_once(copy_worker, [(dsn, p, n) for n, p in enumerate(robots)])
        copy_rate, copy_p99, copied = summary(copy_runs)
        print(f"raw COPY, {args.robots} processes: {copied:,} rows at {copy_rate:,.0f} rows/s "
              f"(p99 batch {copy_p99 * 1e3:.0f} ms)", flush=True)

        central_url = server.database("central")
        process, url = start_central(central_url, scratch / "central.log")
        try:
            contact = first_contact(url, robots + prepared[-1:])
            print(f"first contact of {args.robots + 1} robots (their logs made at the "
                  f"central): {contact * 1e3:.0f} ms each", flush=True)
            spy = None
            if args.profile:  # py-spy (pip install py-spy) samples the central meanwhile
                spy = subprocess.Popen(["py-spy", "record", "--pid", str(process.pid), "-f",
                                        "raw", "-o", args.profile, "--rate", "250"],
                                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                time.sleep(1.0)
            cpu_before = cpu_seconds(process.pid)
            snapshot: list[dict[str, float]] = []  # taken before the projections begin
            push_runs, robots_cpu = all_at_once(push_worker, [(url, p) for p in robots],
                                                lambda: snapshot.append(cpu_seconds(process.pid)))
            cpu_after = snapshot[0]
            if spy is not None:
                spy.send_signal(2)
                spy.wait(60)
            push_rate, push_p99, pushed = summary(push_runs)
            used = {k: (cpu_after[k] - cpu_before[k]) / (args.robots * args.records) * 1e6
                    for k in cpu_before}
            used["robots"] = robots_cpu / (args.robots * args.records) * 1e6
            print(f"  CPU per record: {used['machine']:.0f} µs on the machine, of which the "
                  f"central {used['central']:.0f} µs, PostgreSQL {used['postgresql']:.0f} µs, "
                  f"the robot processes {used['robots']:.0f} µs, the rest (the kernel, "
                  "starting and ending the robot processes) "
                  f"{used['machine'] - used['central'] - used['postgresql'] - used['robots']:.0f}"
                  " µs", flush=True)
            print(f"push, {args.robots} robots: {pushed:,} records at {push_rate:,.0f} "
                  f"records/s (p99 batch acknowledgement {push_p99 * 1e3:.0f} ms)", flush=True)
            projected_rate = projected(url, push_runs)
            print(f"  projected too (statistics by robot answered): {projected_rate:,.0f} "
                  "records/s", flush=True)

            single = [push_worker(url, prepared[-1])()]
            single_rate, single_p99, _ = summary(single)
            raw_single_rate, _, _ = summary([insert_worker(dsn, prepared[-1])])
            print(f"one robot alone: {single_rate:,.0f} records/s (p99 batch "
                  f"{single_p99 * 1e3:.0f} ms); raw psycopg inserts of the same rows "
                  f"{raw_single_rate:,.0f} rows/s", flush=True)
        finally:
            process.terminate()
            process.wait(30)

    print()
    print(f"{args.robots} robots pushing: {push_rate:,.0f} records/s "
          f"{verdict(push_rate >= 30_000)} (target ≥ 30,000)")
    print(f"  vs raw COPY of the same rows: {ratio(push_rate, copy_rate):.2f}× "
          f"{verdict(ratio(push_rate, copy_rate) >= 0.5)} (target ≥ 0.5×)")
    print(f"  p99 batch acknowledgement: {push_p99 * 1e3:.0f} ms "
          f"{verdict(push_p99 <= 0.25)} (target ≤ 250 ms)")
    print(f"  projected as well: {projected_rate:,.0f} records/s (no target; the answer to a "
          "push does not wait for projections)")
    print(f"one robot: {single_rate:,.0f} records/s = "
          f"{ratio(single_rate, raw_single_rate):.2f}× raw psycopg inserts (no target)")
    if args.part == "all":
        with pg_server.running() as server:
            stats_part(server, args.stats_robots, args.stats_records, args.open_logs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
