"""Reads never delay reports (issue "Hardening"): a long statistics query runs on the manager's
read threads while the executor keeps answering reports, and a shutdown waits for it.

The query comes from its own process (tests/ros/drive_stats.py) so that receiving its big
answer does not compete with the report latencies measured here. The bound is relative to
the query's own duration, never an absolute time: this VM varies 2-3x from run to run.
"""

from __future__ import annotations

import json
import queue
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
from tests.ros.processes import LineProcess

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

DRIVER = str(Path(__file__).with_name("drive_stats.py"))
FAILED, PASSED = 0, 1
LONG_QUERY = {"by": "10min", "since": "2025-10-20", "until": "2026-11-20"}
"""56,000+ ten-minute periods (the ledger allows 60,000): seconds of computing here."""
SHORT_QUERY = {"by": "10min", "since": "2026-09-01", "until": "2026-11-20"}
"""About 11,500 periods: long enough to be in flight when SIGTERM arrives."""


def answer_of(line: str) -> dict[str, object]:
    answer: dict[str, object] = json.loads(line.split(" ", 1)[1])
    return answer


@pytest.mark.alone  # other workers' load would slow the answer's send, not the query
def test_reports_are_answered_while_a_long_statistics_query_computes(
        manager: ManagerFactory, client: RosClient, tmp_path: Path) -> None:
    fault_manager = manager()
    client.wait_until_answering()
    stats = LineProcess([sys.executable, DRIVER], tmp_path / "stats.log", timeout=30.0)
    try:
        stats.expect("ready")
        assert client.report("WARM_UP", FAILED, 1, "", "/pytest/reads")
        stats.write(json.dumps(LONG_QUERY))
        latencies: list[float] = []
        line = ""
        deadline = time.monotonic() + 120.0
        n = 0
        while not line:
            start = time.monotonic()
            assert client.report(f"DURING_{n % 10}", n % 2, 1, "", "/pytest/reads")
            latencies.append(time.monotonic() - start)
            n += 1
            try:
                line = stats.lines.get_nowait()
            except queue.Empty:
                assert time.monotonic() < deadline, "the statistics query was not answered"
        answer = answer_of(line)
        assert answer["success"] is True, answer
        assert int(str(answer["rows"])) > 50_000
        duration = float(str(answer["seconds"]))
        assert duration > 1.0, f"the query took {duration:.2f} s: too short to show anything"
        worst = max(latencies)
        assert worst < duration / 4, (
            f"a report waited {worst:.3f} s while the statistics query took {duration:.2f} s "
            f"({len(latencies)} reports)")
        assert len(latencies) >= 20, latencies
        assert fault_manager.running, fault_manager.describe()
    finally:
        stats.write("exit")
        stats.stop()


def test_shutdown_answers_the_reads_in_flight(manager: ManagerFactory, client: RosClient,
                                              tmp_path: Path) -> None:
    fault_manager = manager()
    client.wait_until_answering()
    stats = LineProcess([sys.executable, DRIVER], tmp_path / "stats.log", timeout=30.0)
    try:
        stats.expect("ready")
        stats.write(json.dumps(SHORT_QUERY))
        time.sleep(0.3)  # the request reached the manager, the query computes
        assert fault_manager.stop(signal.SIGTERM) == 0, fault_manager.describe()
        answer = answer_of(stats.expect("stats ", timeout=30.0))
        assert answer["success"] is True, answer
    finally:
        stats.write("exit")
        stats.stop()
