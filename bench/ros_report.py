"""ReportFault round trips per second against the fault manager, next to an rclpy echo service.

Both servers use the same request type, QoS, callback group and executor; the clients are
separate processes with the same call pattern (see _ros_client.py). Runs alternate echo and
faultledger so that this VM's drift hits both alike; the figures are the medians of the rounds.

The physical limit of one sequential client (issue 20) is measured in the same run: an echo
round trip plus one raw durable commit (sqlite3, WAL, synchronous=FULL, one row per commit, as
bench/ingest.py's baseline (a)), i.e. 1 / (1 / echo rate + median commit time). Targets: one
client ≥ 0.8× that limit, four clients ≥ 0.8× the echo service.

Run it in a private network namespace: ``scripts/in-netns .venv/bin/python bench/ros_report.py``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from _common import (
    BENCH_DIR,
    header,
    percentile,
    plan,
    ratio,
    remove_db,
    scratch_dir,
    url_for,
    verdict,
)
from ingest import run_raw

TARGET_RATIO = 0.8
TARGET_SEQUENTIAL = 1_000.0
TARGET_FOUR = 2_000.0


@dataclass
class Run:
    rate: float
    p50_ms: float
    p99_ms: float
    rejected: int
    lost: int = 0
    """Calls whose answer never came (the client gave up after ANSWER_TIMEOUT_S)."""
    commit_ms: float | None = None
    """The raw commit node's median COMMIT inside the node."""


def start_server(kind: str, db: Path, log: Path) -> subprocess.Popen[str]:
    if kind == "echo":
        args = [sys.executable, str(BENCH_DIR / "_ros_echo_server.py")]
    elif kind == "shaped echo":
        args = [sys.executable, str(BENCH_DIR / "_ros_echo_server.py"), "shaped", str(db)]
    elif kind == "raw commit":
        args = [sys.executable, str(BENCH_DIR / "_ros_echo_server.py"), "committing", str(db)]
    else:
        args = [sys.executable, "-m", "faultledger.cli.main", "serve", "--db", url_for(db)]
    server = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=log.open("w"), text=True)
    assert server.stdout is not None
    for line in server.stdout:
        if line.startswith("fault_manager ready"):
            return server
    raise SystemExit(f"{kind} server did not start; see {log}:\n{log.read_text()}")


def stop_server(server: subprocess.Popen[str]) -> str:
    """Stop the server; what it printed after its ready line."""
    server.send_signal(signal.SIGTERM)
    try:
        out, _ = server.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        server.kill()
        out, _ = server.communicate()
    return out or ""


def run_clients(clients: int, calls: int, codes: int) -> Run:
    procs = [subprocess.Popen([sys.executable, str(BENCH_DIR / "_ros_client.py"), str(calls),
                               str(n), str(codes)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
             for n in range(clients)]
    for proc in procs:
        assert proc.stdout is not None
        if proc.stdout.readline().strip() != "ready":
            raise SystemExit("a bench client did not find the service")
    for proc in procs:  # release them together
        assert proc.stdin is not None
        proc.stdin.write("go\n")
        proc.stdin.flush()
    results = []
    for proc in procs:
        out, _ = proc.communicate(timeout=600)
        results.append(json.loads(out.strip().splitlines()[-1]))
    latencies = [x for r in results for x in r["latencies"]]
    elapsed = max(r["elapsed"] for r in results)
    return Run(len(latencies) / elapsed, percentile(latencies, 0.5) * 1e3,
               percentile(latencies, 0.99) * 1e3, sum(r["rejected"] for r in results),
               sum(r["lost"] for r in results))


def measure(kind: str, clients: int, calls: int, codes: int, scratch: Path) -> Run:
    db = scratch / "faults.db"
    remove_db(db)
    remove_db(scratch / "faults.db.raw")
    server = start_server(kind, db, scratch / f"{kind.replace(' ', '-')}.log")
    try:
        run_clients(clients, min(200, calls), codes)  # warm-up: discovery, page cache
        run = run_clients(clients, calls, codes)
    finally:
        printed = stop_server(server)
    for line in printed.splitlines():
        if line.startswith("commit median "):
            run.commit_ms = float(line.split()[2])
    return run


def median_run(runs: list[Run]) -> Run:
    commits = [r.commit_ms for r in runs if r.commit_ms is not None]
    return Run(statistics.median(r.rate for r in runs), statistics.median(r.p50_ms for r in runs),
               statistics.median(r.p99_ms for r in runs), sum(r.rejected for r in runs),
               sum(r.lost for r in runs), statistics.median(commits) if commits else None)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--calls", type=int, default=2000, help="calls per client (default 2000)")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds (default 3)")
    parser.add_argument("--codes", type=int, default=50, help="fault codes per client")
    args = parser.parse_args()
    if os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") != "LOCALHOST":
        sys.exit("run this in a private network namespace: "
                 "scripts/in-netns .venv/bin/python bench/ros_report.py")
    header("ReportFault round trips: faultledger serve vs an rclpy echo service")
    print(f"   {args.rounds} alternating rounds; {args.calls} sequential calls per client "
          f"process; FAILED/PASSED alternating over {args.codes} codes per client")
    with scratch_dir("ros-") as scratch:
        commits = []
        for round_ in range(args.rounds):
            raw_db = scratch / f"raw-{round_}.db"
            commits.append(statistics.median(run_raw(plan(args.calls, args.codes),
                                                     raw_db).latencies))
            remove_db(raw_db)
        commit_s = statistics.median(commits)
        print(f"   raw durable commit (sqlite3, WAL, synchronous=FULL, one row): median "
              f"{commit_s * 1e3:.3f} ms", flush=True)
        for clients in (1, 4):
            runs: dict[str, list[Run]] = {"echo": [], "shaped echo": [], "raw commit": [],
                                          "faultledger": []}
            for _ in range(args.rounds):
                for kind in runs:
                    runs[kind].append(measure(kind, clients, args.calls, args.codes, scratch))
            echo, ours = median_run(runs["echo"]), median_run(runs["faultledger"])
            shaped = median_run(runs["shaped echo"])
            committing = median_run(runs["raw commit"])
            target = TARGET_SEQUENTIAL if clients == 1 else TARGET_FOUR
            share = ratio(ours.rate, echo.rate)
            print(f"-- {clients} client process(es)")
            for name, run in (("echo", echo), ("shaped echo", shaped),
                              ("raw commit", committing), ("faultledger", ours)):
                print(f"   {name:<12} {run.rate:8,.0f} calls/s   p50 {run.p50_ms:6.2f} ms   "
                      f"p99 {run.p99_ms:6.2f} ms   rejected {run.rejected}"
                      + (f"   LOST {run.lost} answers" if run.lost else ""))
            print(f"   ratio {share:.2f}x echo (target >= {TARGET_RATIO}x: "
                  f"{verdict(share >= TARGET_RATIO)}); {ours.rate:,.0f}/s "
                  f"(target >= {target:,.0f}/s: {verdict(ours.rate >= target)})")
            print(f"   information: {ratio(ours.rate, shaped.rate):.2f}x the shaped echo (the "
                  f"fault manager's own node, report_fault answering at once)")
            print(f"   information: {ratio(ours.rate, committing.rate):.2f}x raw commit (the "
                  f"same node answering after one raw sqlite3 durable commit, as ingest (a))")
            if committing.commit_ms is not None:
                print(f"   information: raw commit's COMMIT inside the node: median "
                      f"{committing.commit_ms:.3f} ms (alone, in a loop: {commit_s * 1e3:.3f} ms)")
            if clients == 1:
                limit = 1 / (1 / echo.rate + commit_s)
                print(f"   physical limit (echo round trip + one raw durable commit): "
                      f"{limit:,.0f}/s; ratio {ratio(ours.rate, limit):.2f}x (target >= "
                      f"{TARGET_RATIO}x: {verdict(ratio(ours.rate, limit) >= TARGET_RATIO)})")
                shaped_limit = 1 / (1 / shaped.rate + commit_s)
                print(f"   information: the same limit with the shaped echo's round trip: "
                      f"{shaped_limit:,.0f}/s; ratio {ratio(ours.rate, shaped_limit):.2f}x")
            print("   rounds: " + ", ".join(f"{kind} {[round(r.rate) for r in kind_runs]}"
                                            for kind, kind_runs in runs.items()), flush=True)


if __name__ == "__main__":
    main()
