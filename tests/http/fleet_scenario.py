"""A fleet central with two robots for the tests of its reads over HTTP and in the dashboard
(docs/http.md, "Fleet"): `faultledger http` on a SQLite file with the Berlin three-shift
calendar, and two robot logs pushed to it over HTTP as a robot's sync does.

Each robot log covers the previous and the current shift at times relative to now, and each
record is stamped as written when it happened (a robot writes as things happen; the test
writes hours of log in a second). robot-a pushed everything; robot-b pushed only the first
part of the previous shift (its head_seq says more exists), so every figure of robot-b is
provisional and it is hours behind.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from faultledger import FaultLedger, Policy
from faultledger.domain.clock import to_ns
from faultledger.domain.shifts import ShiftCalendar, ShiftInstance
from faultledger.service import writer
from faultledger.service.config import load_shift_calendar
from tests.cli_stats_scenario import CALENDAR_YAML
from tests.http.conftest import Server, start_server, write_config
from tests.http.test_fleet_api import PUSH, body
from tests.test_fleet_central import records_of

ESTOP = "HW_BASE_EMERGENCY_STOP"
HEALING = Policy(healing_enabled=True, healing_threshold=0)
"""An e-stop's PASSED (its release) heals it; the other faults stay CONFIRMED."""
OWN_FAULT = "CENTRAL_DISK_SLOW"
"""A fault of the central's own log: never among a robot's."""


@dataclass
class Fleet:
    server: Server
    calendar: ShiftCalendar
    current: ShiftInstance
    previous: ShiftInstance
    urls: dict[str, str]
    """Each robot's own log (SQLite URL)."""
    ledger_ids: dict[str, str]


@contextlib.contextmanager
def stamped(clock: list[int]) -> Iterator[None]:
    """The robot's writer stamps records with ``clock[0]`` instead of the wall clock."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(writer, "recorded_clock", lambda: clock[0])
        yield


def write_log(path: Path, robot_id: str, events: list[tuple[datetime, str]]) -> str:
    """``events``: (when, what) with what an e-stop press (``estop``), an aborted goal
    (``aborted``) or a fault code reported FAILED (confirmed at once)."""
    url = f"sqlite:///{path}"
    clock = [to_ns(events[0][0])]
    with stamped(clock), FaultLedger.open(url, policy=HEALING, robot_id=robot_id,
                                          background=False) as robot:
        for n, (at, what) in enumerate(sorted(events)):
            clock[0] = to_ns(at)
            if what == "estop":
                assert robot.report(ESTOP, "FAILED", 3, "e-stop pressed", f"/{robot_id}/plc",
                                    at=at).accepted
                clock[0] = to_ns(at + timedelta(seconds=20))
                assert robot.report(ESTOP, "PASSED", 3, "", f"/{robot_id}/plc",
                                    at=at + timedelta(seconds=20)).accepted
            elif what == "aborted":
                assert robot.record_goal_outcome("/navigate_to_pose", f"goal-{n}", "ABORTED",
                                                 "/bt_navigator", at=at).accepted
            else:
                assert robot.report(what, "FAILED", 2, f"{what} on {robot_id}",
                                    f"/{robot_id}/base", at=at).accepted
    return url


def shifts_now(calendar: ShiftCalendar) -> tuple[ShiftInstance, ShiftInstance]:
    """The current shift and the one before; near a shift's end, wait for the next one (the
    pages read "now" a few seconds later)."""
    now = datetime.now(UTC)
    current = calendar.shift_at(now)
    assert current is not None
    if current.end - now < timedelta(seconds=90):
        time.sleep((current.end - now).total_seconds() + 1)
        now = datetime.now(UTC)
        current = calendar.shift_at(now)
        assert current is not None
    previous = calendar.shift_at(current.start - timedelta(microseconds=1))
    assert previous is not None
    return current, previous


def push(server: Server, url: str, upto: int | None = None) -> tuple[str, int]:
    """Push a robot log (up to seq ``upto``) over HTTP, announcing its whole head; returns
    (ledger_id, the robot's head seq)."""
    robot_id, ledger_id, records = records_of(url)
    head = records[-1].seq
    sent = [r for r in records if upto is None or r.seq <= upto]
    answer = server.client.post(PUSH, json=body(robot_id, ledger_id, sent, head))
    assert answer.status_code == 200, answer.text
    return ledger_id, head


def start_fleet(directory: Path) -> Fleet:
    directory.mkdir(parents=True, exist_ok=True)
    shifts = directory / "shifts.yaml"
    shifts.write_text(CALENDAR_YAML, encoding="utf-8")
    calendar = load_shift_calendar(shifts)
    current, previous = shifts_now(calendar)
    now = datetime.now(UTC)
    span = now - current.start

    def prev(hours: float) -> datetime:
        return previous.start + timedelta(hours=hours)

    def cur(share: float) -> datetime:
        return current.start + span * share

    urls = {
        "robot-a": write_log(directory / "robot-a.db", "robot-a", [
            (prev(1), "estop"), (prev(2), "estop"), (prev(3), "estop"),
            (prev(1.5), "aborted"), (prev(4), "aborted"), (prev(5), "NAV_STUCK"),
            (cur(0.2), "estop"), (cur(0.4), "aborted"), (cur(0.6), "estop"),
            (cur(0.8), "LIDAR_TIMEOUT")]),
        "robot-b": write_log(directory / "robot-b.db", "robot-b", [
            (prev(1), "estop"), (prev(1.5), "GRIPPER_JAM"),
            (prev(6), "estop"), (prev(7), "estop"), (cur(0.5), "estop"),
            (cur(0.7), "aborted")]),
    }
    server = start_server(directory / "central.db", config=write_config(
        directory / "central.yaml", extra={"shifts": str(shifts)}))
    try:
        assert server.client.post("/api/v1/reports", json={
            "fault_code": OWN_FAULT, "event_type": "FAILED", "severity": 1,
            "source_id": "/central"}).json()["accepted"]
        ledger_ids = {"robot-a": push(server, urls["robot-a"])[0]}
        with FaultLedger.open(urls["robot-b"]) as robot_b:  # up to the gripper jam
            jam = max(r.seq for r in robot_b.history("GRIPPER_JAM"))
        ledger_ids["robot-b"] = push(server, urls["robot-b"], upto=jam)[0]
    except BaseException:
        server.stop()
        raise
    return Fleet(server, calendar, current, previous, urls, ledger_ids)
