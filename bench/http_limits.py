"""HTTP limits (issue 18): memory and fault-list latency under 8 and 40 concurrent heaviest
statistics requests, and 1,100 slow connections under a 1,024 open-files limit against the
same app on plain uvicorn. Real servers in subprocesses on 127.0.0.1; the interactive client
(`_http_probe.py`) is a process of its own.

Usage: .venv/bin/python bench/http_limits.py [--quick] [--heavy-reads N] [--heavy-only]
"""

from __future__ import annotations

import argparse
import json
import resource
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx

from _common import BENCH_DIR, header, percentile, ratio, scratch_dir, url_for, verdict
from faultledger import FaultLedger, ReportRequest
from http_api import READY

HEAVIEST = "/api/v1/stats?by=10min&since=2026-01-01T00:00Z&until=2026-03-11T09:00Z"
"""9,990 periods of 10 minutes: the largest answer http.max_stats_rows (10,000) allows."""
MEMORY_BOUND_MB = 150
"""docs/http.md, "Limits": growth over the size at start with the default limits."""
P99_TARGET = 0.1
SLOW = 1100
OPEN_FILES = 1024


def seed(db: Path, reports: int) -> None:
    start = datetime(2026, 1, 1, tzinfo=UTC)
    step = timedelta(days=69) / reports
    with FaultLedger.open(url_for(db)) as ledger:
        for first in range(0, reports, 5000):
            ledger.report_many([
                ReportRequest(f"BENCH_{i % 200:03d}", "FAILED" if i % 3 else "PASSED", 2, "",
                              f"/cell/{i % 7}", start + i * step)
                for i in range(first, min(reports, first + 5000))])


def memory_kb(pid: int) -> dict[str, int]:
    status = Path(f"/proc/{pid}/status").read_text()
    return {line.split(":")[0]: int(line.split()[1]) for line in status.splitlines()
            if line.startswith(("VmRSS", "VmHWM"))}


@contextmanager
def serving(command: list[str], log: Path) -> Iterator[tuple[str, int]]:
    """A server process; yields its URL (from its ready line) and its pid."""
    with log.open("w") as out:
        proc = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60
        while not (found := READY.search(log.read_text())):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError("no ready line:\n" + log.read_text())
            time.sleep(0.05)
        yield found.group(1), proc.pid
    finally:
        proc.terminate()
        proc.wait(10)


@contextmanager
def probing(url: str, seconds: float) -> Iterator[dict[str, list[float]]]:
    out: dict[str, list[float]] = {}
    proc = subprocess.Popen([sys.executable, str(BENCH_DIR / "_http_probe.py"), url,
                             str(seconds)], stdout=subprocess.PIPE, text=True)
    try:
        yield out
    finally:
        text, _ = proc.communicate(timeout=seconds + 60)
        out.update(json.loads(text))


def burst(url: str, count: int) -> tuple[dict[int, int], float]:
    codes: dict[int, int] = {}
    lock = threading.Lock()

    def one() -> None:
        with httpx.Client(base_url=url, timeout=120) as client, client.stream(
                "GET", HEAVIEST) as answer:
            for _ in answer.iter_raw():
                pass
            with lock:
                codes[answer.status_code] = codes.get(answer.status_code, 0) + 1

    started = time.monotonic()
    threads = [threading.Thread(target=one) for _ in range(count)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return codes, time.monotonic() - started


def ms(values: list[float], q: float) -> str:
    return f"{percentile(values, q) * 1e3:.1f}"


def bench_heavy(folder: Path, quick: bool, slots: int) -> bool:
    header(f"8 and 40 concurrent heaviest GET /api/v1/stats (9,990 periods) vs GET "
           f"/api/v1/faults; http.heavy_reads {slots}")
    db = folder / "heavy.db"
    seed(db, 5000 if quick else 20000)
    config = folder / "c.yaml"
    config.write_text(f"http:\n  tokens_file: null\n  heavy_reads: {slots}\n")
    good = True
    with serving([sys.executable, "-m", "faultledger.cli.main", "http", "--db", str(db),
                  "--listen", "127.0.0.1:0", "--config", str(config)],
                 folder / "heavy.log") as (url, pid):
        httpx.get(url + "api/v1/faults", timeout=30)
        at_start = memory_kb(pid)["VmRSS"]
        with probing(url, 5) as idle:
            pass
        print(f"server at start: {at_start / 1024:.0f} MB; GET /api/v1/faults alone: p50 "
              f"{ms(idle['latencies'], 0.5)} ms, p99 {ms(idle['latencies'], 0.99)} ms")
        started = time.perf_counter()
        single = httpx.get(url + HEAVIEST.lstrip("/"), timeout=60)
        one = time.perf_counter() - started
        print(f"one heaviest request alone: {one:.2f} s, {len(single.content) / 1e6:.1f} MB "
              f"answer, {len(single.json()['items'])} rows")
        for count in (8, 40):
            with probing(url, 12 if quick else 16) as probe:
                time.sleep(0.5)
                codes, took = burst(url, count)
            grown = (memory_kb(pid)["VmHWM"] - at_start) / 1024
            p99 = percentile(probe["latencies"], 0.99)
            fine = grown < MEMORY_BOUND_MB and p99 < P99_TARGET and not probe["failures"]
            good = good and fine
            print(f"{count:2d} at once: answers {dict(sorted(codes.items()))} in {took:.1f} s; "
                  f"peak growth {grown:.0f} MB (bound {MEMORY_BOUND_MB}); GET /api/v1/faults "
                  f"meanwhile: {len(probe['latencies'])} answers, p50 "
                  f"{ms(probe['latencies'], 0.5)} ms, p99 {p99 * 1e3:.1f} ms, max "
                  f"{max(probe['latencies']) * 1e3:.1f} ms (p99 ratio to alone "
                  f"{ratio(p99, percentile(idle['latencies'], 0.99)):.1f}): {verdict(fine)}")
    return good


def slow_connections(url: str, count: int, wait: float) -> tuple[int, str, int]:
    """``count`` sockets that send part of a request head; then a normal client; then, after
    ``wait`` s, how many of the slow sockets the server closed."""
    host, port = url.removeprefix("http://").rstrip("/").rsplit(":", 1)
    head = f"GET /api/v1/faults HTTP/1.1\r\nHost: {host}:{port}\r\nX-Slow: ".encode()
    sockets = []
    for _ in range(count):
        sock = socket.socket()
        sock.settimeout(10)
        try:
            sock.connect((host, int(port)))
            sock.sendall(head)
        except OSError:
            sock.close()
            break
        sockets.append(sock)
    started = time.monotonic()
    try:
        answer = httpx.get(url + "api/v1/faults", timeout=10)
        normal = f"{answer.status_code} in {(time.monotonic() - started) * 1e3:.0f} ms"
    except httpx.HTTPError as error:
        normal = f"failed after {time.monotonic() - started:.1f} s ({type(error).__name__})"
    time.sleep(wait)
    closed = 0
    for sock in sockets:
        sock.setblocking(False)
        try:
            sock.recv(65536)
            closed += 1
        except BlockingIOError:
            pass
        except OSError:
            closed += 1
        sock.close()
    return len(sockets), normal, closed


def limited(command: list[str]) -> list[str]:
    """``command`` under a soft open-files limit of OPEN_FILES."""
    return [sys.executable, "-c",
            "import os, resource, sys; h = resource.getrlimit(resource.RLIMIT_NOFILE)[1]; "
            f"resource.setrlimit(resource.RLIMIT_NOFILE, ({OPEN_FILES}, h)); "
            "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])", *command[1:]]


def bench_slow(folder: Path) -> bool:
    header(f"{SLOW:,} connections sending a partial request head, server limited to "
           f"{OPEN_FILES:,} open files")
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, max(soft, 2 * SLOW)), hard))
    db = folder / "slow.db"
    seed(db, 100)
    config = folder / "slow.yaml"
    config.write_text("http:\n  tokens_file: null\n")
    ours_cmd = [sys.executable, "-m", "faultledger.cli.main", "http", "--db", str(db),
                "--listen", "127.0.0.1:0", "--config", str(config)]
    with serving(limited(ours_cmd), folder / "ours.log") as (url, _):
        opened, normal, closed = slow_connections(url, SLOW, 12)
    print(f"faultledger  : {opened} opened; a normal GET /api/v1/faults: {normal}; closed by "
          f"the server 12 s later: {closed} of {opened}")
    plain_cmd = [sys.executable, str(BENCH_DIR / "_http_plain_uvicorn.py"), str(db)]
    with serving(limited(plain_cmd), folder / "plain.log") as (url, _):
        p_opened, p_normal, p_closed = slow_connections(url, SLOW, 12)
    print(f"plain uvicorn: {p_opened} opened; a normal GET /api/v1/faults: {p_normal}; closed "
          f"by the server 12 s later: {p_closed} of {p_opened}")
    good = normal.startswith("200") and closed == opened
    print(f"answered and every slow connection closed: {verdict(good)}")
    return good


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller data, shorter probes")
    parser.add_argument("--heavy-reads", type=int, default=1, metavar="N",
                        help="http.heavy_reads of the server (default 1, the default)")
    parser.add_argument("--heavy-only", action="store_true", help="skip the connections")
    args = parser.parse_args()
    with scratch_dir("http-limits-") as folder:
        heavy = bench_heavy(folder, args.quick, args.heavy_reads)
        slow = args.heavy_only or bench_slow(folder)
    print(f"\nHTTP limits bench: heavy reads {verdict(heavy)}, slow connections {verdict(slow)}")


if __name__ == "__main__":
    main()
