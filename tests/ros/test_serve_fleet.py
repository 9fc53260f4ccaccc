"""`faultledger serve` with the config's ``fleet:``: the fault manager pushes its log to a
fleet central on a thread of its own (docs/fleet.md, "Robot side"). A report made over ROS
reaches a real central (`faultledger http` on a SQLite file, on loopback inside the test's
network namespace) within about a second; SIGTERM stops the manager and its pusher (exit 0)."""

from __future__ import annotations

import json
import sqlite3
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
import yaml
from tests.fleet_central import Central, robot_hashes, robot_token, wait_for

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient


@pytest.fixture
def central(tmp_path: Path) -> Iterator[Central]:
    started = Central.start(tmp_path / "central", str(tmp_path / "central" / "central.db"))
    yield started
    started.stop()


def ledger_id_of(db: Path) -> str:
    """From the log's own identity record (the projections are saved behind the commits)."""
    with sqlite3.connect(db) as conn:
        (payload,) = conn.execute("SELECT payload FROM events WHERE kind = 'ledger_identified' "
                                  "ORDER BY seq LIMIT 1").fetchone()
    return str(json.loads(payload)["ledger_id"])


def test_serve_pushes_each_report_to_the_central_within_a_second(
        tmp_path: Path, central: Central, manager: ManagerFactory, client: RosClient) -> None:
    token = robot_token(central, "robot-ros", tmp_path / "robot.token")
    config = tmp_path / "robot.yaml"
    config.write_text(yaml.safe_dump({
        "robot_id": "robot-ros", "http": {"tokens_file": None},
        "fleet": {"central": central.url, "token_file": str(token)}}))
    served = manager("--config", str(config))
    assert wait_for(lambda: any(line.startswith(f"fleet: pushing this log to {central.url}")
                                for line in served.stdout_lines), 5), served.describe()
    ledger_id = ledger_id_of(served.db_path)
    # serve identifies the log and records its policy when it starts: pushed at once.
    assert wait_for(lambda: central.last_seq(ledger_id) >= 2, 5), served.describe()
    for number in range(5):
        sent = time.monotonic()
        assert client.report(f"ROS_FLEET_{number}", 0, 2, "from ROS", "/ros/node")
        head = robot_hashes(served.db_path)[-1][0]
        assert wait_for(lambda h=head: central.last_seq(ledger_id) >= h, 5, 0.02), \
            served.describe()
        assert time.monotonic() - sent < 1.5
    assert served.stop() == 0, served.describe()
    assert central.hashes(ledger_id) == robot_hashes(served.db_path)
