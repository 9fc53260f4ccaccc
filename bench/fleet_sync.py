"""Robot side of the fleet: how fast one `faultledger sync` catches a PostgreSQL central up,
and how soon `sync --follow` delivers a new record (docs/operations.md, "A robot offline").

- **catch-up**: a robot log of N records (SQLite, made through ``FaultLedger.report_many``) is
  pushed by one real `faultledger sync` process into a fresh central (`faultledger http --db
  postgresql+psycopg://…`, tokens on, the robot's own token). Figures: the process's wall time
  (start to exit, Python start-up and opening the log included) and the rate its caught-up line
  gives. N = 10,000 and 100,000 by default.
- **follow**: `sync --follow` on a log that gets one report every 0.2 s; the delay from each
  report's commit to the central's last_seq reaching it (polled every 10 ms). p50 and max.

The PostgreSQL server is started here, as the tests do (tests/pg_server.py).
"""

from __future__ import annotations

import argparse
import re
import signal
import sys
import time
from pathlib import Path

from _common import ROOT, header, percentile, scratch_dir

sys.path.insert(0, str(ROOT))
from tests import pg_server
from tests.fleet_central import Central, add_reports, robot_log, robot_token, start_sync, sync

from faultledger import FaultLedger

RATE = re.compile(r"pushed (\d+) records in ([0-9.]+) s \(([0-9,]+) records/s\)")


def catch_up(scratch: Path, server: pg_server.PostgresServer, records: int) -> None:
    central = Central.start(scratch / f"central-{records}", server.database("central"))
    try:
        robot = scratch / f"robot-{records}.db"
        made = time.monotonic()
        robot_id, ledger_id = robot_log(robot, records)
        print(f"robot log of {records:,} records made in {time.monotonic() - made:.1f} s "
              f"({robot.stat().st_size / records:.0f} bytes a record on disk)", flush=True)
        token = robot_token(central, robot_id, scratch / f"robot-{records}.token")
        started = time.monotonic()
        done = sync(robot, central, token, timeout=600)
        wall = time.monotonic() - started
        assert done.returncode == 0, done.stderr
        found = RATE.search(done.stdout)
        assert found is not None, done.stdout
        assert central.last_seq(ledger_id) == records
        print(f"catch-up {records:,} records: process {wall:.2f} s ({records / wall:,.0f} "
              f"records/s end to end); its own line: {found.group(2)} s, {found.group(3)} "
              "records/s", flush=True)
    finally:
        central.stop()


def follow(scratch: Path, server: pg_server.PostgresServer, reports: int) -> None:
    central = Central.start(scratch / "central-follow", server.database("follow"))
    robot = scratch / "robot-follow.db"
    robot_id, ledger_id = robot_log(robot, 100)
    token = robot_token(central, robot_id, scratch / "robot-follow.token")
    follower = start_sync(robot, central.url, token, scratch / "follow.log", "--follow")
    delays = []
    try:
        deadline = time.monotonic() + 30
        while central.last_seq(ledger_id) < 100 and time.monotonic() < deadline:
            time.sleep(0.05)
        with FaultLedger.open(f"sqlite:///{robot}", robot_id=robot_id) as ledger:
            for _ in range(reports):
                add_reports(ledger, 1, "FOLLOW")
                committed, seq = time.monotonic(), ledger.last_seq
                while central.last_seq(ledger_id) < seq:
                    time.sleep(0.01)
                delays.append(time.monotonic() - committed)
                time.sleep(0.2)
        follower.send_signal(signal.SIGTERM)
        code = follower.wait(10)
    finally:
        if follower.poll() is None:
            follower.kill()
        central.stop()
    print(f"follow: {reports} reports, commit -> central p50 {percentile(delays, 0.5) * 1000:.0f}"
          f" ms, max {max(delays) * 1000:.0f} ms; SIGTERM exit {code}", flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--records", type=int, nargs="*", default=[10_000, 100_000])
    parser.add_argument("--follow-reports", type=int, default=50)
    args = parser.parse_args()
    header("fleet sync: one robot catching a PostgreSQL central up")
    with scratch_dir("fleet-sync") as scratch, pg_server.running() as server:
        for records in args.records:
            catch_up(scratch, server, records)
        follow(scratch, server, args.follow_reports)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
