"""The fleet's acceptance scenario (issue 19, docs/fleet.md), with real processes only.

Three robots, each a Python process writing back-dated reports, clears and goal outcomes into
its own SQLite log while `faultledger sync --follow` (one per robot, each with its own robot
token) pushes it to a central: `faultledger http` on a real PostgreSQL database. While they
run:

- a sync is killed (SIGKILL) mid-batch and started again;
- a robot's token is used to push another robot's log: 403;
- a robot's database is replaced (a new file, the same robot_id): a second chain;
- the central is stopped while the robots keep writing (a burst each), and a record that was
  not pushed yet is edited on one robot (sqlite3 UPDATE of its payload);
- the central is started again and killed (SIGKILL) while it takes the backlog, then started
  again on the same database: the following syncs recover by themselves.

Afterwards every robot log at the central equals the robot's own, record for record and hash
for hash (the edited one up to the record before the edit, where its sync stopped), each chain
verifies, and the per-shift per-robot statistics at the central equal each robot's own figure
for figure (the Europe/Berlin calendar with the shipped config/shifts.yaml's three shifts:
tests/cli_stats_scenario.CALENDAR_YAML).

The scenario runs once for the module (``fleet_run``); the tests check what it left.
"""

from __future__ import annotations

import contextlib
import json
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any
from zoneinfo import ZoneInfo

import pytest

from faultledger import FaultLedger
from faultledger.domain.shifts import ShiftCalendar
from faultledger.service.audit import export_history
from faultledger.service.config import load_shift_calendar
from faultledger.service.fleet import Fleet
from faultledger.store.event_log import StoredRecord
from tests.cli_stats_scenario import CALENDAR_YAML
from tests.fleet_central import (
    CLI,
    Central,
    robot_hashes,
    robot_token,
    start_sync,
    wait_for,
)
from tests.pg_server import PostgresServer

BERLIN = ZoneInfo("Europe/Berlin")
BURST = 2000
"""Records a robot writes at once on SIGUSR1 (while the central is away)."""

WRITER = r"""
import random, signal, sys, time
from datetime import datetime, timedelta
from faultledger import FaultLedger, Policy, ReportRequest

path, robot_id, seed, initial, burst, base, end = sys.argv[1:8]
rng = random.Random(int(seed))
start, stop_at = datetime.fromisoformat(base), datetime.fromisoformat(end)
flags = {"stop": False, "bursts": 0}
signal.signal(signal.SIGTERM, lambda *_: flags.update(stop=True))
signal.signal(signal.SIGUSR1, lambda *_: flags.update(bursts=flags["bursts"] + 1))
CODES = ["HW_BASE_EMERGENCY_STOP", "NAV_STUCK", "LIDAR_TIMEOUT", "MOTOR_OVERHEAT"]
deadline = time.monotonic() + 300  # never outlive a test that lost track of this process
n = 0


def write(ledger, count):
    global n
    reports = []

    def flush():
        if reports:
            results = ledger.report_many(reports)
            assert all(r.accepted for r in results), [r for r in results if not r.accepted]
            reports.clear()

    for _ in range(count):
        at = start + timedelta(seconds=12 * n + rng.randrange(12))
        if at >= stop_at:
            break
        n += 1
        code, roll = rng.choice(CODES), rng.random()
        if roll < 0.04:
            flush()
            ledger.clear(code, actor="operator", reason="checked", at=at)
        elif roll < 0.10:
            flush()
            done = ledger.record_goal_outcome(
                "/navigate_to_pose", f"{robot_id}-{seed}-{n}",
                rng.choice(["ABORTED", "SUCCEEDED", "CANCELED"]), "/bt_navigator", at=at)
            assert done.accepted, done
        else:
            reports.append(ReportRequest(code, "FAILED" if roll < 0.6 else "PASSED",
                                         rng.randrange(1, 4), f"r{n}",
                                         f"/{robot_id}/{code.lower()}", at))
            if len(reports) == 500:
                flush()
    flush()


policy = Policy(healing_enabled=True, healing_threshold=0)
with FaultLedger.open(f"sqlite:///{path}", policy=policy, robot_id=robot_id,
                      background=False) as ledger:
    write(ledger, int(initial))
    print("ready", ledger.last_seq, flush=True)
    while not flags["stop"] and time.monotonic() < deadline:
        if flags["bursts"]:
            flags["bursts"] -= 1
            write(ledger, int(burst))
            print("burst", ledger.last_seq, flush=True)
        write(ledger, 10)
        time.sleep(0.1)
    print("stopped", ledger.last_seq, n, flush=True)
"""
"""A robot: writes ``initial`` items at once, then 10 every 0.1 s (and ``burst`` at once on
SIGUSR1) until SIGTERM; item n happens at ``base`` + 12 s * n (plus up to 11 s: some 2,400
items a shift), never at or after ``end``."""


def tail(path: Path, lines: int = 30) -> str:
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return f"--- {path.name}: no output"
    return f"--- {path.name} (last {lines} lines):\n" + "\n".join(text.splitlines()[-lines:])


@dataclass
class Robot:
    """One robot: its log, its writer process and its sync process (with their output)."""

    robot_id: str
    path: Path
    token: Path
    directory: Path
    writer: subprocess.Popen[str] | None = None
    sync: subprocess.Popen[str] | None = None
    logs: list[Path] = field(default_factory=list)
    """The writer's output, then each sync's."""

    @property
    def url(self) -> str:
        return f"sqlite:///{self.path}"

    def start_writer(self, seed: int, initial: int, base: datetime, end: datetime) -> None:
        log = self.directory / f"writer-{self.path.stem}.log"
        self.logs.append(log)
        with log.open("w") as out:
            self.writer = subprocess.Popen(
                [sys.executable, "-c", WRITER, str(self.path), self.robot_id, str(seed),
                 str(initial), str(BURST), base.isoformat(), end.isoformat()],
                stdout=out, stderr=subprocess.STDOUT, text=True, stdin=subprocess.DEVNULL)

    def start_sync(self, central: Central) -> None:
        log = self.directory / f"sync-{self.path.stem}-{len(self.logs)}.log"
        self.logs.append(log)
        self.sync = start_sync(self.path, central.url, self.token, log, "--follow")

    def head(self) -> int:
        """The log's newest seq, read with sqlite3 (0 before the log exists)."""
        if not self.path.exists():
            return 0
        with contextlib.closing(sqlite3.connect(self.path, timeout=10)) as conn:
            return int(conn.execute("SELECT coalesce(max(seq), 0) FROM events").fetchone()[0])

    def ledger_id(self) -> str:
        with contextlib.closing(sqlite3.connect(self.path, timeout=10)) as conn:
            payload = conn.execute("SELECT payload FROM events WHERE kind = "
                                   "'ledger_identified'").fetchone()[0]
        return str(json.loads(payload)["ledger_id"])

    def writer_said(self, word: str) -> bool:
        return word in self.logs[0].read_text(errors="replace")

    def sync_log(self) -> str:
        """The output of its current sync."""
        return self.logs[-1].read_text(errors="replace")

    def output(self) -> str:
        return "\n".join(tail(log) for log in self.logs)


def stop_process(process: subprocess.Popen[str] | None, sig: int = signal.SIGTERM,
                 timeout: float = 15) -> int | None:
    if process is None:
        return None
    if process.poll() is None:
        process.send_signal(sig)
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode


@dataclass(frozen=True)
class Chain:
    """A robot log as the scenario left it: what the central must hold of it."""

    robot_id: str
    ledger_id: str
    url: str
    path: Path
    head: int
    held: int
    """The seq the central must hold up to (the head; the record before the edit)."""


@dataclass
class FleetRun:
    central: Central
    chains: list[Chain]
    edited_seq: int
    calendar: ShiftCalendar
    since: datetime
    until: datetime
    as_of: datetime
    seen: dict[str, Any] = field(default_factory=dict)
    """What the scenario observed on the way (outputs, kill points, timings)."""

    @contextlib.contextmanager
    def fleet(self) -> Iterator[Fleet]:
        with FaultLedger.open(self.central.db, background=False,
                              calendar=self.calendar) as ledger, Fleet(ledger) as robot_logs:
            yield robot_logs

    def chain(self, robot_id: str) -> list[Chain]:
        return [c for c in self.chains if c.robot_id == robot_id]


class Scenario:
    """The run: a central, three robots, the bounded waits (failing with every output)."""

    def __init__(self, directory: Path, central: Central) -> None:
        self.directory = directory
        self.central = central
        self.robots: list[Robot] = []
        self.started = time.monotonic()
        self.timings: dict[str, float] = {}

    def robot(self, robot_id: str, file: str) -> Robot:
        """A robot (its token made on the central by the caller: robot_token)."""
        found = Robot(robot_id, self.directory / file, self.directory / f"{robot_id}.token",
                      self.directory)
        self.robots.append(found)
        return found

    def outputs(self) -> str:
        logs = [tail(r, 40) for r in self.central.directory.glob("central-*.log")]
        return "\n".join([*(r.output() for r in self.robots), *logs])

    def wait(self, condition: Callable[[], bool], timeout: float, what: str) -> None:
        if not wait_for(condition, timeout, 0.05):
            raise AssertionError(f"{what}: not within {timeout:g} s (at "
                                 f"{time.monotonic() - self.started:.1f} s of the run)\n"
                                 f"central chains: {self.held_safely()}\n{self.outputs()}")

    def mark(self, phase: str) -> None:
        self.timings[phase] = round(time.monotonic() - self.started, 1)

    def held(self) -> dict[str, int]:
        """ledger_id -> last_seq, as GET /api/v1/fleet/robots says."""
        return {str(c["ledger_id"]): int(c["last_seq"]) for c in self.central.robots()}

    def held_safely(self) -> dict[str, int] | str:
        try:
            return self.held()
        except Exception as error:  # the central is away: say so in the failure
            return f"(cannot ask the central: {error})"

    def ready(self, robot: Robot) -> None:
        self.wait(lambda: robot.writer_said("ready"), 60,
                  f"{robot.robot_id}'s writer did not write its first records")

    def kill_children(self) -> None:
        for robot in self.robots:
            stop_process(robot.writer, signal.SIGKILL)
            stop_process(robot.sync, signal.SIGKILL)
        self.central.stop(signal.SIGKILL)


@pytest.fixture(scope="module")
def fleet_run(tmp_path_factory: pytest.TempPathFactory,
              postgres_server: PostgresServer) -> Iterator[FleetRun]:
    directory = tmp_path_factory.mktemp("fleet-acceptance")
    shifts = directory / "shifts.yaml"
    shifts.write_text(CALENDAR_YAML, encoding="utf-8")
    midnight = datetime.now(BERLIN).replace(hour=0, minute=0, second=0, microsecond=0)
    since = midnight - timedelta(days=3)
    until = midnight
    base = since + timedelta(hours=2)
    central = Central.start(directory / "central", postgres_server.database("acceptance"))
    run = Scenario(directory, central)
    try:
        yield play(run, load_shift_calendar(shifts), since, until, base)
    finally:
        run.kill_children()


class OneShot:
    """`faultledger sync` (once) in the background, for its exit code and output later."""

    def __init__(self, robot: Robot, central: Central, token: Path) -> None:
        self.process = subprocess.Popen(
            [*CLI, "sync", "--db", str(robot.path), "--central", central.url, "--token-file",
             str(token)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            stdin=subprocess.DEVNULL)

    def result(self) -> subprocess.CompletedProcess[str]:
        try:
            out, err = self.process.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            self.process.kill()
            out, err = self.process.communicate()
            raise AssertionError(f"a one-shot sync did not end within 60 s:\n{out}{err}"
                                 ) from None
        return subprocess.CompletedProcess(self.process.args, self.process.returncode, out,
                                           err)


def play(run: Scenario, calendar: ShiftCalendar, since: datetime, until: datetime,
         base: datetime) -> FleetRun:
    central = run.central
    seen: dict[str, Any] = {}
    r0, r1, r2 = (run.robot(f"robot-{n}", f"robot-{n}.db") for n in range(3))
    end = until - timedelta(hours=1)
    r0.start_writer(0, 4000, base, end)
    r1.start_writer(1, 1000, base, end)
    r2.start_writer(2, 1000, base, end)
    for robot in (r0, r1, r2):  # while the writers start: each robot's token on the central
        robot_token(central, robot.robot_id, robot.token)
    for robot in (r0, r1, r2):
        run.ready(robot)
    run.mark("writers ready")

    # -- a sync killed mid-batch, started again; robot-1's token for robot-2's log -----------
    r1.start_sync(central)
    r2.start_sync(central)
    r0.start_sync(central)
    forbidden = OneShot(r2, central, r1.token)
    ledger0 = r0.ledger_id()
    run.wait(lambda: run.held().get(ledger0, 0) > 0, 30, "robot-0's first batch at the central")
    assert stop_process(r0.sync, signal.SIGKILL) == -signal.SIGKILL
    seen["sync killed at"] = (run.held().get(ledger0, 0), r0.head())
    held, head = seen["sync killed at"]
    assert head - held > 1000, f"robot-0's sync was killed after its backlog: {held} of {head}"
    r0.start_sync(central)
    run.mark("sync killed and started again")

    # -- robot-2's database replaced: its old log pushed whole, then a new log ---------------
    assert stop_process(r2.writer) == 0, r2.output()
    old2 = Chain("robot-2", r2.ledger_id(), r2.url, r2.path, r2.head(), r2.head())
    run.wait(lambda: run.held().get(old2.ledger_id) == old2.head, 30,
             "robot-2's old log wholly at the central")
    assert stop_process(r2.sync) == 0, r2.output()
    seen["old robot-2 sync"] = r2.sync_log()
    r2b = run.robot("robot-2", "robot-2-new.db")
    r2b.start_writer(22, 500, base + timedelta(hours=30), end)
    run.ready(r2b)
    r2b.start_sync(central)
    seen["forbidden"] = forbidden.result()
    writing = (r0, r1, r2b)
    heads = {r.ledger_id(): r.head() for r in writing}
    run.wait(lambda: all(run.held().get(lid, 0) >= h for lid, h in heads.items()), 40,
             "the robots' logs caught up at the central")
    run.mark("robot-2 replaced, all caught up")

    # -- the central away while the robots keep writing; an edit before it was pushed --------
    before = run.held()
    central.stop()
    down = time.monotonic()
    stopped_heads = {r.ledger_id(): r.head() for r in writing}
    for robot in writing:
        assert robot.writer is not None
        robot.writer.send_signal(signal.SIGUSR1)
    ledger1, ledger2b = r1.ledger_id(), r2b.ledger_id()
    edit_from = stopped_heads[ledger1] + 30
    run.wait(lambda: r1.head() >= edit_from + 100, 20,
             "robot-1 writing while the central is away")
    edited = edit_record(r1.path, edit_from)
    run.wait(lambda: all(r.writer_said("burst ") for r in writing), 30,
             "the robots' bursts written")
    time.sleep(max(0.0, 3.0 - (time.monotonic() - down)))
    for robot in writing:
        assert robot.sync is not None and robot.sync.poll() is None, robot.output()
    central.run()
    seen["central away s"] = round(time.monotonic() - down, 1)
    run.mark("central back")

    # -- the central killed while it takes the backlog ---------------------------------------
    behind = {lid: h for lid, h in stopped_heads.items() if lid != ledger1}
    run.wait(lambda: any(run.held().get(lid, 0) > before[lid] for lid in behind), 40,
             "a backlog arriving at the central")
    central.stop(signal.SIGKILL)
    killed_held = held_in_logs(central, behind)
    seen["central killed at"] = {lid: (killed_held.get(lid), next(
        r.head() for r in writing if r.ledger_id() == lid)) for lid in behind}
    assert any(head - held >= 500 for held, head in seen["central killed at"].values()), \
        f"the central took the whole backlog before it was killed: {seen['central killed at']}"
    central.run()
    run.mark("central killed and started again")

    # -- the robots stop writing; the syncs catch up by themselves ----------------------------
    time.sleep(0.5)
    for robot in writing:
        assert stop_process(robot.writer) == 0, robot.output()
    run.mark("writers stopped")
    final = {r.ledger_id(): r.head() for r in writing}
    expected = {**final, ledger1: edited - 1, old2.ledger_id: old2.head}
    run.wait(lambda: run.held() == expected, 60,
             f"the central holding every log up to its head ({expected})")
    run.wait(lambda: f"refused the batch at seq {edited}" in r1.sync_log(), 20,
             "robot-1's sync naming the edited record")
    run.mark("caught up after the kills")
    edited_once = OneShot(r1, central, r1.token)
    for robot in writing:
        assert stop_process(robot.sync) == 0, robot.output()
        seen[f"sync log {robot.path.stem}"] = "\n".join(
            log.read_text(errors="replace") for log in robot.logs[1:])
    seen["edited once"] = edited_once.result()
    run.mark("done")
    seen["timings"] = run.timings
    chains = [Chain("robot-0", ledger0, r0.url, r0.path, final[ledger0], final[ledger0]),
              Chain("robot-1", ledger1, r1.url, r1.path, final[ledger1], edited - 1),
              old2,
              Chain("robot-2", ledger2b, r2b.url, r2b.path, final[ledger2b], final[ledger2b])]
    print(f"fleet acceptance: {run.timings}; sync killed at {seen['sync killed at']}, central "
          f"killed at {seen['central killed at']}, away {seen['central away s']} s, edited seq "
          f"{edited}; heads { {c.robot_id + ':' + c.ledger_id[:8]: c.head for c in chains} }")
    return FleetRun(central, chains, edited, calendar, since, until, until, seen)


def held_in_logs(central: Central, ledger_ids: dict[str, int]) -> dict[str, int]:
    """How far the central's logs go, read from PostgreSQL while the central is down (its
    directory may lag its logs after a kill: the logs are what counts)."""
    with FaultLedger.open(central.db, background=False) as ledger, Fleet(ledger) as fleet:
        found = {}
        for chain in fleet.chains():
            if chain.ledger_id in ledger_ids:
                with fleet.log(chain) as log:
                    found[chain.ledger_id] = log.last_seq
        return found


def edit_record(path: Path, from_seq: int) -> int:
    """Edit the description of the first report at or after ``from_seq`` (sqlite3, as an
    intruder would, the hash left as it was); its seq."""
    with contextlib.closing(sqlite3.connect(path, timeout=10)) as conn:
        seq, payload = conn.execute(
            "SELECT seq, payload FROM events WHERE seq >= ? AND kind = 'fault_reported' "
            "ORDER BY seq LIMIT 1", (from_seq,)).fetchone()
        changed = payload.replace('"description":"r', '"description":"edited r')
        assert changed != payload, payload
        conn.execute("UPDATE events SET payload = ? WHERE seq = ?", (changed, seq))
        assert conn.total_changes == 1
        conn.commit()
    return int(seq)


def robot_rows(url: str) -> list[StoredRecord]:
    with FaultLedger.open(url, create=False, upgrade=False, background=False) as robot:
        return list(export_history(robot))


def figures(row: Any) -> dict[str, Any]:
    found: dict[str, Any] = row.as_dict()
    for name in ("robot", "line", "site", "ledger_id", "complete"):
        found.pop(name, None)
    return found


# -- what the run left -----------------------------------------------------------------------
def test_every_robot_log_at_the_central_equals_the_robots_own_record_for_record(
        fleet_run: FleetRun) -> None:
    listed = {(c["robot_id"], c["ledger_id"]): c for c in fleet_run.central.robots()}
    assert set(listed) == {(c.robot_id, c.ledger_id) for c in fleet_run.chains}
    assert [c["robot_id"] for c in fleet_run.central.robots()] == [
        "robot-0", "robot-1", "robot-2", "robot-2"]  # robot-2's replaced database: 2 chains
    with fleet_run.fleet() as fleet:
        for chain in fleet_run.chains:
            status = listed[(chain.robot_id, chain.ledger_id)]
            assert (status["last_seq"], status["records"]) == (chain.held, chain.held)
            own = robot_rows(chain.url)[:chain.held]
            held = list(fleet.history(chain.robot_id, chain.ledger_id))
            assert {identity for identity, _ in held} == {(chain.robot_id, chain.ledger_id)}
            assert len(held) == chain.held
            for (_, at_central), at_robot in zip(held, own, strict=True):
                assert at_central == at_robot, (chain.robot_id, at_central.seq)
            assert fleet_run.central.hashes(chain.ledger_id) == robot_hashes(
                chain.path)[:chain.held]
            [check] = fleet.verify(chain.robot_id, chain.ledger_id)
            assert check.report.ok, check.report
            assert check.report.records == chain.held


def test_per_shift_per_robot_statistics_at_the_central_equal_the_robots_own(
        fleet_run: FleetRun) -> None:
    run = fleet_run
    with run.fleet() as fleet:
        at_central = fleet.stats("shift", run.since, run.until, group_by=["robot"],
                                 as_of=run.as_of)
    counted = 0
    for chain in run.chains:
        if chain.held != chain.head:
            continue  # the edited log: the central holds a prefix (compared record for record)
        several = len(run.chain(chain.robot_id)) > 1
        rows = [row for row in at_central if row.group["robot"] == chain.robot_id
                and (not several or row.group["ledger_id"] == chain.ledger_id)]
        with FaultLedger.open(chain.url, create=False, upgrade=False, background=False,
                              calendar=run.calendar) as robot:
            own = robot.stats("shift", run.since, run.until, as_of=run.as_of)
        assert len(own) >= 9  # three days of the calendar's three shifts (and a night)
        assert [figures(row) for row in rows] == [figures(row) for row in own], chain
        assert all(row.complete for row in rows)
        busy = [row for row in own if row.activations]
        assert len(busy) >= 2, f"{chain}: the log's reports fall in one shift only"
        assert sum(row.estops for row in own) and sum(row.aborted_goals for row in own)
        assert any(row.mttr_seconds for row in own)
        counted += 1
    assert counted == 3


def test_the_edited_log_stops_at_the_edit_and_the_central_keeps_everything_before_it(
        fleet_run: FleetRun) -> None:
    [chain] = fleet_run.chain("robot-1")
    edited = fleet_run.edited_seq
    assert chain.held == edited - 1 < chain.head
    following = fleet_run.seen["sync log robot-1"]
    assert (f"refused the batch at seq {edited} (422 broken-chain: record {edited} does not "
            "match its hash") in following, following
    assert f"nothing from seq {edited} on is pushed" in following
    once = fleet_run.seen["edited once"]
    assert once.returncode == 1, once.stdout + once.stderr
    assert (f"refused the batch at seq {edited} (422 broken-chain: record {edited} does not "
            "match its hash") in once.stderr, once.stderr
    assert f"the central holds seq {edited - 1} of {chain.head}" in once.stderr
    assert fleet_run.central.last_seq(chain.ledger_id) == edited - 1


def test_a_robots_token_cannot_push_another_robots_log(fleet_run: FleetRun) -> None:
    refused = fleet_run.seen["forbidden"]
    assert refused.returncode == 1, refused.stdout + refused.stderr
    assert (f"error: the central {fleet_run.central.url} refused the token (403 forbidden: "
            "token 'robot-1' may push only the logs of robot robot-1, not 'robot-2')"
            ) in refused.stderr, refused.stderr


def test_the_syncs_recovered_from_the_kills_and_the_central_away_by_themselves(
        fleet_run: FleetRun) -> None:
    seen = fleet_run.seen
    held, head = seen["sync killed at"]
    assert 0 < held < head
    assert any(0 < (held or 0) < head for held, head in seen["central killed at"].values())
    for name in ("robot-0", "robot-2-new"):
        log = seen[f"sync log {name}"]
        assert "cannot reach the central" in log, log
        assert "takes records again" in log, log
    old = seen["old robot-2 sync"]
    [chain] = [c for c in fleet_run.chain("robot-2") if c.path.name == "robot-2.db"]
    assert f"stopped (SIGTERM); the central holds seq {chain.head} of {chain.head}" in old, old
