"""Goal outcomes end to end, with real rclpy action servers.

``drive_count_action.py`` serves two actions (``faultledger_test_actions/action/Count``, built
for the session by ``count_action.py``) and sends them goals that end as told. The
action-status bridge watches ``/whole/count`` inside ``faultledger serve`` (default judgement,
``whole_array``) and ``/fresh/count`` standalone (``judge: new_goals``). Each action runs abort,
abort, succeed, abort; the servers keep finished goals (rclpy's result_timeout, 900 s), so
every status array carries the aborted goals. Then both bridges restart and get the servers'
latched arrays again, and one more goal ends per action. Checked: the fault reports of both
judgements, and that the manager counts every goal exactly once (``~/get_statistics`` with
``group_by: [action, source]``, and ``FaultLedger.stats`` on the database afterwards).

Also here: ``~/report_goal_outcome`` called directly (idempotence, refusals, a burst), and a
FaultReporter's goal outcomes queued while no manager runs.
"""

from __future__ import annotations

import json
import sys
import time
import uuid
from collections.abc import Iterator
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from builtin_interfaces.msg import Time
from faultledger_msgs.srv import GetStatistics, ReportGoalOutcome
from tests.ros import count_action
from tests.ros.processes import LineProcess
from tests.ros.test_bridge_action_status import Proc, reports, wait_for

from faultledger import FaultLedger
from faultledger.domain.clock import from_ns
from faultledger.domain.events import GOAL_OUTCOME
from faultledger.ros.reporter import FaultReporter

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

DRIVER = Path(__file__).with_name("drive_count_action.py")
WHOLE, FRESH = "/whole/count", "/fresh/count"
WHOLE_CODE = "ACTION_WHOLE_COUNT_ABORTED"
FRESH_CODE = "ACC_D_FRESH_COUNT_ABORTED"  # code_prefix "acc-d", upper-snake-cased
SERVER = "/count_server"
STATUS_OF = {"abort": "ABORTED", "succeed": "SUCCEEDED", "cancel": "CANCELED"}
FAILED, PASSED = ("FAILED", SERVER), ("PASSED", SERVER)
Counts = dict[tuple[str, str], tuple[int, int, int]]
"""(action, server node) → (aborted, canceled, succeeded) goals."""


@pytest.fixture(scope="session")
def count_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The environment of a process that imports the Count action (built once per session)."""
    prefix = count_action.build(tmp_path_factory.mktemp("count_action"))
    return count_action.environment(prefix)


class CountDriver(LineProcess):
    stop_wait_sec = 15.0

    def __init__(self, tmp_path: Path, env: dict[str, str], *actions: str) -> None:
        super().__init__([sys.executable, str(DRIVER), *actions], tmp_path / "count-driver.log",
                         timeout=30.0, env=env)
        self.expect("driver ready")

    def goal(self, action: str, outcome: str) -> str:
        """Send one goal, wait for its result; the goal's UUID text."""
        line = self.ask(["goal", action, outcome], "goal ", 30.0)
        _, goal_id, status = line.split()
        assert status == STATUS_OF[outcome], line
        return goal_id


def now_us() -> int:
    """Now in ns, whole microseconds (statistics bounds must be)."""
    return time.time_ns() // 1000 * 1000


def stamp(ns: int) -> Any:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def goal_counts(client: RosClient, since_ns: int, until_ns: int) -> Counts:
    response = client.call(GetStatistics, "/fault_manager/get_statistics", GetStatistics.Request(
        by="day", since_time=stamp(since_ns), until_time=stamp(until_ns),
        group_by=["action", "source"]))
    assert (response.success, response.message) == (True, "")
    counts: dict[tuple[str, str], list[int]] = {}
    for row in response.rows:
        total = counts.setdefault((row.action, row.source), [0, 0, 0])
        for i, value in enumerate((row.aborted_goals, row.canceled_goals, row.succeeded_goals)):
            total[i] += value
    return {key: (a, c, s) for key, (a, c, s) in counts.items()}


class Bridge(Proc):
    """``faultledger bridge action-status`` on ``config``."""

    def __init__(self, tmp_path: Path, config: Path, run: int) -> None:
        super().__init__([sys.executable, "-m", "faultledger.cli.main", "bridge",
                          "action-status", "--config", str(config)],
                         tmp_path / f"bridge-{run}.log")
        self.expect("bridge ready: action_status")


@pytest.fixture
def stop_at_end() -> Iterator[list[LineProcess]]:
    running: list[LineProcess] = []
    yield running
    for proc in reversed(running):
        proc.stop()


def test_goal_outcomes_are_counted_once_and_faults_follow_the_judgement(
        manager: ManagerFactory, client: RosClient, tmp_path: Path, count_env: dict[str, str],
        stop_at_end: list[LineProcess]) -> None:
    serve_config = tmp_path / "serve.yaml"
    serve_config.write_text(yaml.safe_dump({"bridges": {"action_status": {
        "enabled": True, "rescan_period_sec": 0.5, "include_only_actions": ["/whole/"]}}}))
    bridge_config = tmp_path / "bridge.yaml"
    bridge_config.write_text(yaml.safe_dump({
        "rescan_period_sec": 0.5, "judge": "new_goals", "include_only_actions": ["/fresh/"],
        "code_prefix": "acc-d"}))
    start = now_us()
    fm = manager("--config", str(serve_config))
    bridge = Bridge(tmp_path, bridge_config, 1)
    stop_at_end.append(bridge)
    warning = "action_status.code_prefix='acc-d' is not upper snake case; using 'ACC_D'"
    wait_for("code_prefix warning", lambda: warning in bridge.stderr(), 10.0, bridge.stderr)
    driver = CountDriver(tmp_path, count_env, WHOLE, FRESH)
    stop_at_end.append(driver)
    logs = {WHOLE: fm.stderr_text, FRESH: bridge.stderr}

    def why() -> str:
        return (f"manager:\n{fm.stderr_text()[-3000:]}\nbridge:\n{bridge.stderr()[-3000:]}\n"
                f"driver:\n{driver.stderr()[-2000:]}")

    def logged(action: str, line: str) -> bool:
        return line in logs[action]()

    def run(outcome: str) -> dict[str, str]:
        """One goal per action; returns when each bridge has logged the goal's status."""
        goals = {action: driver.goal(action, outcome) for action in (WHOLE, FRESH)}
        for action, goal_id in goals.items():
            line = f"action {action}: goal {goal_id} {STATUS_OF[outcome]}"
            wait_for(line, partial(logged, action, line), why=why)
        return goals

    # abort, abort, succeed, abort, one goal at a time, each seen by the bridges before the next.
    first = run("abort")
    wait_for("raised at the first abort", lambda: reports(client, WHOLE_CODE) == [FAILED]
             and reports(client, FRESH_CODE) == [FAILED], why=why)
    assert client.fault(WHOLE_CODE).description == \
        f"action {WHOLE}: goal {first[WHOLE]} ABORTED"
    run("abort")
    run("succeed")
    run("abort")
    middle = now_us()
    period = {(WHOLE, SERVER): (3, 0, 1), (FRESH, SERVER): (3, 0, 1)}
    wait_for("3 aborted and 1 succeeded goals per action",
             lambda: goal_counts(client, start, middle) == period, why=why)
    # whole_array: raised once; the success did not heal (the aborted goals are still in the
    # array). new_goals: the success healed at once and the next abort raised again.
    wait_for("new_goals healed and raised again",
             lambda: reports(client, FRESH_CODE) == [FAILED, PASSED, FAILED], why=why)
    assert reports(client, WHOLE_CODE) == [FAILED]

    # Both bridges restart (the manager with its own): each gets the server's latched array
    # with all four goals again and sends their outcomes again; nothing is counted twice.
    # A restarted bridge starts healthy, so the aborted goals in that array raise again.
    bridge.stop()
    fm.stop()
    fm.start()
    bridge = Bridge(tmp_path, bridge_config, 2)
    stop_at_end.append(bridge)
    logs[FRESH] = bridge.stderr
    wait_for("raised again after the restarts",
             lambda: reports(client, WHOLE_CODE) == [FAILED, FAILED]
             and reports(client, FRESH_CODE) == [FAILED, PASSED, FAILED, FAILED], why=why)
    # One more goal per action: its outcome is sent after the repeated ones, on the same
    # client, so once it is counted the repeats have been answered (as duplicates).
    last = {WHOLE: driver.goal(WHOLE, "succeed"), FRESH: driver.goal(FRESH, "cancel")}
    end = now_us()
    wait_for("the last goals counted", lambda: goal_counts(client, start, end) == {
        (WHOLE, SERVER): (3, 0, 2), (FRESH, SERVER): (3, 1, 1)}, why=why)
    assert goal_counts(client, start, middle) == period
    # whole_array: aborted goals still in the array, no heal; new_goals: a cancel (no fault
    # here) is a terminal goal, so it heals.
    wait_for("new_goals healed by the cancel", lambda: reports(client, FRESH_CODE) == [
        FAILED, PASSED, FAILED, FAILED, PASSED], why=why)
    assert reports(client, WHOLE_CODE) == [FAILED, FAILED]

    # The database on its own: one record per goal, the same counts.
    assert fm.stop() == 0
    with FaultLedger.open(fm.url, upgrade=False, create=False) as ledger:
        records = ledger.history(kinds=[GOAL_OUTCOME])
        assert len(records) == 10
        assert {(r.payload["action"], r.payload["goal_id"]) for r in records} >= {
            (WHOLE, first[WHOLE]), (FRESH, first[FRESH]), (WHOLE, last[WHOLE]),
            (FRESH, last[FRESH])}
        assert {r.payload["server_node"] for r in records} == {SERVER}
        rows = ledger.stats(by="day", since=from_ns(start), until=from_ns(end),
                            group_by=["action"])
        totals: dict[str, list[int]] = {}
        for row in rows:
            total = totals.setdefault(str(row.group["action"]), [0, 0, 0])
            for i, value in enumerate((row.aborted_goals, row.canceled_goals,
                                       row.succeeded_goals)):
                total[i] += value
        assert totals == {WHOLE: [3, 0, 2], FRESH: [3, 1, 1]}


# -- the service and the reporter ------------------------------------------------------------------
SERVICE = "/fault_manager/report_goal_outcome"


def outcome(goal: int, status: str = "ABORTED", **fields: Any) -> Any:
    values: dict[str, Any] = {"action": "/nav", "goal_id": str(uuid.UUID(int=goal)),
                              "status": status, "server_node": "/nav_server", **fields}
    return ReportGoalOutcome.Request(**values)


def goal_records(client: RosClient) -> list[Any]:
    return list(client.history(kinds=[GOAL_OUTCOME]).records)


def test_report_goal_outcome_is_idempotent_and_refuses_bad_input(
        manager: ManagerFactory, client: RosClient) -> None:
    manager()
    client.wait_until_answering()
    at = 1_795_000_000_123_456_000
    answer = client.call(ReportGoalOutcome, SERVICE, outcome(1, stamp=stamp(at)))
    assert (answer.accepted, answer.duplicate, answer.message) == (True, False, "")
    # The same goal again (another status, another time): stored once, the first wins.
    answer = client.call(ReportGoalOutcome, SERVICE, outcome(1, "SUCCEEDED"))
    assert (answer.accepted, answer.duplicate, answer.message) == (True, True, "")
    for request, message in [
            (outcome(2, "LOST"), "status must be SUCCEEDED, ABORTED or CANCELED, got"),
            (outcome(3, action=""), "action cannot be empty"),
            (outcome(4, stamp=Time(sec=1, nanosec=1_000_000_000)),
             "stamp.nanosec must be below 1,000,000,000")]:
        answer = client.call(ReportGoalOutcome, SERVICE, request)
        assert (answer.accepted, answer.duplicate) == (False, False)
        assert answer.message.startswith(message), answer.message
    [record] = goal_records(client)
    assert record.occurred_at == stamp(at)
    assert json.loads(record.payload_json) == {
        "action": "/nav", "goal_id": str(uuid.UUID(int=1)), "status": "ABORTED",
        "server_node": "/nav_server"}
    # A burst, every goal twice, with bad requests among them: each answered on its own.
    burst = [outcome(100 + n % 150, "SUCCEEDED") for n in range(300)]
    burst[10] = outcome(99, "LOST")
    burst[20] = outcome(98, stamp=Time(sec=-1))
    answers = client.call_all(ReportGoalOutcome, SERVICE, burst)
    assert all(a is not None for a in answers)
    assert [n for n, a in enumerate(answers) if not a.accepted] == [10, 20]
    assert answers[20].message == "stamp must not be before 1970 (sec >= 0), got sec=-1"
    assert sum(a.duplicate for a in answers) == 148  # goals 110 and 120 sent once
    assert len(goal_records(client)) == 151


def test_a_reporter_queues_goal_outcomes_until_the_manager_answers(
        manager: ManagerFactory, client: RosClient) -> None:
    fm = manager(start=False)
    reporter = FaultReporter(client.node, "/test/goals", local_filtering=False)
    try:
        goal = str(uuid.UUID(int=7))
        at = 1_795_000_000_000_001_000
        assert reporter.report_goal_outcome("/dock", goal, "CANCELED", server_node="/dock",
                                            stamp_ns=at)
        # Unusable input is refused here (a NUL would cut the string short on the way).
        assert not reporter.report_goal_outcome("/dock", goal, "LOST")
        assert not reporter.report_goal_outcome("/do\x00ck", goal, "ABORTED")
        assert not reporter.report_goal_outcome("/dock", goal, "ABORTED", stamp_ns=-1)
        client.spin_for(0.5)
        assert reporter.pending == 1
        fm.start()
        assert client.spin_until(lambda: reporter.pending == 0, 30.0), fm.describe()
        # Sent again (a restarted bridge would): answered as a duplicate, stored once.
        assert reporter.report_goal_outcome("/dock", goal, "CANCELED", server_node="/dock",
                                            stamp_ns=at)
        assert client.spin_until(lambda: reporter.pending == 0, 30.0)
        [record] = goal_records(client)
        assert record.occurred_at == stamp(at)
        assert json.loads(record.payload_json) == {
            "action": "/dock", "goal_id": goal, "status": "CANCELED", "server_node": "/dock"}
    finally:
        reporter.destroy()
