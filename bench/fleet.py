"""Fleet ingest: robot processes pushing their logs concurrently into one central on PostgreSQL.

What it measures (docs/performance.md, "Fleet"), each against a baseline in the same run:

- **push**: ROBOTS processes, each holding a real robot log (SQLite, RECORDS records made
  through ``FaultLedger.report``), push it to a central (``faultledger http --db
  postgresql+psycopg://…``) in batches of 500 over HTTP, as ``faultledger sync`` does, all
  at once. Figures: records/s into the central (all records / wall time from the first push
  to the last answer), p99 of one batch's acknowledgement. Baseline: the same rows written with
  one ``COPY`` per batch (psycopg) into a table of the same columns in the same PostgreSQL, from
  the same number of processes: the server's raw ingest, no checks.
- **single robot**: one robot pushing alone, against raw psycopg inserts (executemany, one
  transaction per 1,000 rows) of the same rows.

Targets (issue 19): ≥ 30,000 records/s and ≥ 0.5× raw COPY, p99 batch ≤ 250 ms.

The PostgreSQL server is started here, as the tests do (tests/pg_server.py: Debian's
postgresql 15, run as the ``postgres`` user on a loopback port, data in a temporary directory).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from _common import ROOT, header, percentile, ratio, scratch_dir, verdict

sys.path.insert(0, str(ROOT))
from tests import pg_server

from faultledger import FaultLedger, Policy
from faultledger.service.audit import export_history

BATCH = 500
"""Records per push, as `faultledger sync` sends them."""
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


def batches_of(path: Path) -> tuple[str, str, list[dict[str, Any]]]:
    """The robot's log as the push bodies ``faultledger sync`` sends."""
    with FaultLedger.open(f"sqlite:///{path}") as robot:
        identity = robot.identity
        assert identity is not None
        rows = list(export_history(robot))
    head = rows[-1].seq
    bodies = []
    for start in range(0, len(rows), BATCH):
        part = rows[start:start + BATCH]
        bodies.append({"robot_id": identity.robot_id, "ledger_id": identity.ledger_id,
                       "head_seq": head, "records": [{
                           "seq": r.seq, "event_id": r.event_id, "kind": r.kind,
                           "fault_code": r.fault_code, "source_id": r.source_id,
                           "payload": r.payload_json, "occurred_at_ns": r.occurred_at_ns,
                           "recorded_at_ns": r.recorded_at_ns,
                           "schema_version": r.schema_version, "hash": r.hash,
                           "prev_hash": r.prev_hash} for r in part]})
    return identity.robot_id, identity.ledger_id, bodies


def push_worker(args: tuple[str, str, Any]) -> list[tuple[float, float, int]]:
    """(start, end, records) of every batch one robot pushed, in order."""
    import httpx

    url, path, start_at = args
    _, _, bodies = batches_of(Path(path))
    encoded = [json.dumps(body).encode() for body in bodies]
    times = []
    with httpx.Client(base_url=url, timeout=60.0) as client:
        while time.time() < start_at:
            time.sleep(0.001)
        for body, raw in zip(bodies, encoded, strict=True):
            began = time.time()
            answer = client.post("/api/v1/fleet/records", content=raw,
                                 headers={"content-type": "application/json"})
            if answer.status_code != 200:
                raise RuntimeError(f"push refused: {answer.status_code} {answer.text[:300]}")
            times.append((began, time.time(), len(body["records"])))
    return times


def copy_worker(args: tuple[str, str, Any, int]) -> list[tuple[float, float, int]]:
    """The same rows with one COPY per batch into a plain table (the raw baseline)."""
    import psycopg

    dsn, path, start_at, chain = args
    _, _, bodies = batches_of(Path(path))
    times = []
    with psycopg.connect(dsn) as conn:
        while time.time() < start_at:
            time.sleep(0.001)
        for body in bodies:
            began = time.time()
            with conn.cursor() as cursor, cursor.copy(
                    "COPY raw_records (chain_id, " + ", ".join(COLUMNS) + ") FROM STDIN") as copy:
                for r in body["records"]:
                    copy.write_row((chain, *(r[c] for c in COLUMNS)))
            conn.commit()
            times.append((began, time.time(), len(body["records"])))
    return times


def insert_worker(dsn: str, path: str) -> list[tuple[float, float, int]]:
    """Raw psycopg inserts (executemany, one transaction per batch) of one robot's rows."""
    import psycopg

    _, _, bodies = batches_of(Path(path))
    times = []
    sql = ("INSERT INTO raw_records (chain_id, " + ", ".join(COLUMNS) + ") VALUES ("
           + ", ".join(["%s"] * (len(COLUMNS) + 1)) + ")")
    with psycopg.connect(dsn) as conn:
        for body in bodies:
            began = time.time()
            with conn.cursor() as cursor:
                cursor.executemany(sql, [(999, *(r[c] for c in COLUMNS))
                                         for r in body["records"]])
            conn.commit()
            times.append((began, time.time(), len(body["records"])))
    return times


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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=20)
    parser.add_argument("--records", type=int, default=5_000, help="records per robot log")
    args = parser.parse_args()
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
        import psycopg

        with psycopg.connect(dsn, autocommit=True) as conn:
            conn.execute("CREATE TABLE raw_records (chain_id integer, seq bigint, "
                         "event_id varchar(36), kind varchar(40), fault_code varchar(128), "
                         "source_id text, payload text, occurred_at_ns bigint, "
                         "recorded_at_ns bigint, schema_version integer, hash varchar(64), "
                         "PRIMARY KEY (chain_id, seq))")
        robots = [str(p) for p in paths[:args.robots]]
        with multiprocessing.Pool(args.robots) as pool:
            at = time.time() + 3.0
            copy_runs = pool.map(copy_worker, [(dsn, p, at, n) for n, p in enumerate(robots)])
        copy_rate, copy_p99, copied = summary(copy_runs)
        print(f"raw COPY, {args.robots} processes: {copied:,} rows at {copy_rate:,.0f} rows/s "
              f"(p99 batch {copy_p99 * 1e3:.0f} ms)", flush=True)

        central_url = server.database("central")
        process, url = start_central(central_url, scratch / "central.log")
        try:
            with multiprocessing.Pool(args.robots) as pool:
                at = time.time() + 3.0
                push_runs = pool.map(push_worker, [(url, p, at) for p in robots])
            push_rate, push_p99, pushed = summary(push_runs)
            print(f"push, {args.robots} robots: {pushed:,} records at {push_rate:,.0f} "
                  f"records/s (p99 batch acknowledgement {push_p99 * 1e3:.0f} ms)", flush=True)

            single = [push_worker((url, str(paths[-1]), time.time()))]
            single_rate, single_p99, _ = summary(single)
            raw_single_rate, _, _ = summary([insert_worker(dsn, str(paths[-1]))])
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
    print(f"one robot: {single_rate:,.0f} records/s = "
          f"{ratio(single_rate, raw_single_rate):.2f}× raw psycopg inserts (no target)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
