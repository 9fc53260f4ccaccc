"""Alerts (issue 21): ingest with alert delivery on vs off in the same run, and how long a
confirmation takes to reach a webhook receiver at 100 confirmations/s.

The receiver is a threaded http.server on 127.0.0.1 in a process of its own, noting when
each idempotency key arrived; the deliverer is the one `serve` and `faultledger http` run
(faultledger.alerts), in this process beside the ledger, as in a serving process.
"""

from __future__ import annotations

import argparse
import http.client
import json
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from _common import (
    BENCH_DIR,
    header,
    percentile,
    plan,
    report_concurrently,
    scratch_dir,
    url_for,
)
from _common import verdict as verdict_of
from faultledger import FaultLedger, Policy
from faultledger.alerts.deliverer import AlertDeliverer
from faultledger.service.config import AlertRule

RULE = "bench"


class Receiver:
    """The receiver process (bench/_alert_receiver.py): when each key first arrived."""

    def __init__(self) -> None:
        self.process = subprocess.Popen([sys.executable, str(BENCH_DIR / "_alert_receiver.py")],
                                        stdout=subprocess.PIPE, text=True)
        assert self.process.stdout is not None
        port = int(self.process.stdout.readline())
        self.url = f"http://127.0.0.1:{port}/hook"
        self._connection = http.client.HTTPConnection("127.0.0.1", port, timeout=30)

    def arrivals(self) -> dict[str, float]:
        self._connection.request("GET", "/arrivals")
        found: dict[str, float] = json.loads(self._connection.getresponse().read())
        return found

    def wait_for(self, count: int, timeout: float) -> dict[str, float]:
        deadline = time.monotonic() + timeout
        found = self.arrivals()
        while len(found) < count and time.monotonic() < deadline:
            time.sleep(0.05)
            found = self.arrivals()
        return found

    def close(self) -> None:
        self._connection.close()
        self.process.terminate()
        self.process.wait()


@contextmanager
def serving(db: Path, alerts: bool, on: list[str]) -> Iterator[tuple[FaultLedger, Receiver]]:
    """A serving process's ledger (policy, timers) with or without its deliverer."""
    receiver = Receiver()
    ledger = FaultLedger.open(url_for(db), policy=Policy())
    deliverer = None
    try:
        if alerts:
            rule = AlertRule.model_validate({"name": RULE, "on": on, "receiver": {
                "type": "webhook", "url": receiver.url}})
            deliverer = AlertDeliverer(ledger, [rule])
            deliverer.start()
        yield ledger, receiver
    finally:
        if deliverer is not None:
            deliverer.stop()
        ledger.close()
        receiver.close()


@dataclass(frozen=True)
class Ingest:
    rate: float
    delivered: int
    drain_seconds: float


def run_ingest(work: list[tuple[str, str, str]], threads: int, db: Path, alerts: bool
               ) -> Ingest:
    with serving(db, alerts, ["fault_confirmed", "fault_cleared"]) as (ledger, receiver):
        ledger.report("BENCH_WARMUP", "FAILED", severity=2, source_id="/bench/warmup")
        seconds, rejected, _ = report_concurrently(ledger, work, threads)
        if rejected:
            raise SystemExit(f"{rejected} reports were rejected")
        end = time.time()
        expected = len({code for code, _, _ in work}) + 1 if alerts else 0
        found = receiver.wait_for(expected, 120) if alerts else {}
        drained = max(found.values(), default=end) - end
        return Ingest(len(work) / seconds, len(found), max(0.0, drained))


def run_latency(db: Path, per_second: float, seconds: float) -> tuple[list[float], int]:
    """Confirmations (CRITICAL faults of new codes) at a steady rate; per confirmation the
    time from its durable report (the call returned) to its arrival at the receiver."""
    with serving(db, True, ["fault_confirmed"]) as (ledger, receiver):
        identity = ledger.identity
        assert identity is not None
        count = int(per_second * seconds)
        done: dict[str, float] = {}
        start = time.perf_counter()
        for i in range(count):
            delay = start + i / per_second - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            result = ledger.report(f"LATENCY_{i:06d}", "FAILED", severity=3,
                                   source_id="/bench/latency")
            done[f"{identity.ledger_id}:{result.seq}:{RULE}"] = time.time()
        arrivals = receiver.wait_for(count, 30)
        latencies = [arrivals[key] - at for key, at in done.items() if key in arrivals]
        return latencies, count - len(latencies)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="small sizes, one round")
    parser.add_argument("--reports", type=int, default=None,
                        help="reports per ingest run (default 20000, --quick 3000)")
    parser.add_argument("--codes", type=int, default=None,
                        help="codes of the ingest runs: each confirms once (default a tenth "
                        "of the reports)")
    parser.add_argument("--threads", type=int, default=8)
    parser.add_argument("--rounds", type=int, default=None,
                        help="rounds of ingest without/with alerts, medians kept (default 5)")
    parser.add_argument("--rate", type=float, default=100.0,
                        help="confirmations per second of the latency run")
    parser.add_argument("--seconds", type=float, default=None,
                        help="length of the latency run (default 30, --quick 10)")
    args = parser.parse_args()
    n = args.reports or (3000 if args.quick else 20_000)
    n_codes = args.codes or max(1, n // 10)
    rounds = args.rounds or (1 if args.quick else 5)
    seconds = args.seconds or (10.0 if args.quick else 30.0)
    work = plan(n, n_codes)
    header(f"alerts: ingest of {n:,} reports over {n_codes:,} codes ({args.threads} threads) "
           f"without and with a webhook rule on fault_confirmed/fault_cleared, {rounds} "
           f"round(s) in alternating order; then {args.rate:g} confirmations/s for "
           f"{seconds:g} s")
    off: list[Ingest] = []
    on: list[Ingest] = []
    for r in range(rounds):
        # The order alternates: the second run of a round meets the first one's writes
        # still being flushed by the kernel (identical runs differ by up to 10 % here).
        with scratch_dir("alerts-") as workdir:
            for alerts in ((False, True) if r % 2 == 0 else (True, False)):
                (on if alerts else off).append(run_ingest(
                    work, args.threads, workdir / f"{'on' if alerts else 'off'}.db", alerts))
        print(f"   round {r + 1}: without {off[-1].rate:,.0f}/s, with {on[-1].rate:,.0f}/s "
              f"({on[-1].delivered:,} alerts delivered, the last {on[-1].drain_seconds:.2f} s "
              "after the last report)", flush=True)
    rate_off = statistics.median(x.rate for x in off)
    rate_on = statistics.median(x.rate for x in on)
    ratios = [b.rate / a.rate for a, b in zip(off, on, strict=True)]
    with scratch_dir("alerts-latency-") as workdir:
        latencies, missing = run_latency(workdir / "latency.db", args.rate, seconds)
    p50, p99 = percentile(latencies, 0.5), percentile(latencies, 0.99)
    print()
    print(f"   ingest without alerts (median)        {rate_off:>10,.0f} reports/s")
    print(f"   ingest with alerts (median)           {rate_on:>10,.0f} reports/s")
    print(f"   with / without, per round             "
          f"{', '.join(f'{r:.2f}' for r in ratios)} (median {statistics.median(ratios):.2f})")
    print(f"   confirmation -> webhook delivered      p50 {p50 * 1e3:.0f} ms, p99 "
          f"{p99 * 1e3:.0f} ms, max {max(latencies, default=float('nan')) * 1e3:.0f} ms over "
          f"{len(latencies):,} confirmations ({missing} not delivered)")
    print()
    checks = [
        ("ingest with alerts vs without (round median)", statistics.median(ratios), 0.9,
         ">=", "x"),
        (f"delivery p99 at {args.rate:g} confirmations/s", p99, 1.0, "<=", " s"),
    ]
    for name, value, target, sense, unit in checks:
        ok = value >= target if sense == ">=" else value <= target
        ok = ok and (missing == 0 or sense == ">=")
        print(f"   {name:<42} {value:>9.2f}{unit}  target {sense} {target:g}{unit}  "
              f"{verdict_of(ok)}")


if __name__ == "__main__":
    main()
