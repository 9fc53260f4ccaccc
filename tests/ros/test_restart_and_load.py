"""Restart (SIGTERM and kill -9) and load from several client processes (SPEC §3, §5, §8).

* Restart: the same list/get/entity/history answers after the restart, no event re-announced,
  and the debounce counters continue where they stopped.
* Load: 4 client processes report concurrently (one request at a time each, then all at once in
  a burst of 500 each); every request is answered, every accepted report is in the log exactly
  once (read with the Python API after the manager has stopped), nothing rejected is.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from faultledger import FaultLedger

if TYPE_CHECKING:
    from tests.ros.conftest import EventRecorder, ManagerFactory, RosClient

FAILED, PASSED = 0, 1
ALL_STATUSES = ("PREFAILED", "PREPASSED", "CONFIRMED", "HEALED", "CLEARED")
SYNC_PREFIX = "SYNC_"


# -- restart ---------------------------------------------------------------------------------------
def snapshot(client: RosClient) -> dict[str, Any]:
    """Everything a client can read, for before/after comparison (messages compare by value)."""
    everything = client.list_faults(ALL_STATUSES)
    return {
        "list_all": everything,
        "list_default": client.list_faults(),
        "list_critical": client.list_faults(ALL_STATUSES, severity=3),
        "get": {f.fault_code: client.fault(f.fault_code) for f in everything},
        "entity": list(client.for_entity("sensor").faults),
        "history": [(r.seq, r.event_id, r.kind, r.hash, r.payload_json)
                    for r in client.history().records],
    }


def non_sync(messages: list[Any]) -> list[tuple[str, str, str]]:
    return [(m.event_type, m.fault.fault_code, m.fault.status) for m in messages
            if not m.fault.fault_code.startswith(SYNC_PREFIX)]


@pytest.mark.parametrize("how", ["SIGTERM", "kill -9"])
def test_restart_restores_state_without_reannouncing(
        manager: ManagerFactory, client: RosClient, events: EventRecorder, how: str) -> None:
    fault_manager = manager("--ros-args", "-p", "confirmation_threshold:=-3",
                            "-p", "healing_enabled:=true", "-p", "healing_threshold:=3")
    events.wait_matched()
    steps: list[tuple[str, int, int, str]] = [
        ("R_A", FAILED, 1, "/restart/a"), ("R_A", FAILED, 2, "/restart/a2"),  # -2 PREFAILED
        ("R_B", FAILED, 1, "/restart/b"), ("R_B", FAILED, 1, "/restart/b"),
        ("R_B", FAILED, 1, "/restart/b"),                                    # -3 CONFIRMED
        ("R_B", PASSED, 0, "/restart/b"),                                    # -2 CONFIRMED
        ("R_C", FAILED, 3, "/restart/c"),                                    # CONFIRMED
        ("R_D", FAILED, 0, "/robot/sensor"), ("R_D", PASSED, 0, "/robot/sensor"),  # 0 PREFAILED
        ("R_E", FAILED, 3, "/restart/e/sensor"),                             # CONFIRMED
    ]
    for code, event_type, severity, source in steps:
        assert client.report(code, event_type, severity, f"{code} {severity}", source)
    assert client.clear("R_C").success
    statuses = {f.fault_code: f.status for f in client.list_faults(ALL_STATUSES)
                if not f.fault_code.startswith(SYNC_PREFIX)}
    assert statuses == {"R_A": "PREFAILED", "R_B": "CONFIRMED", "R_C": "CLEARED",
                        "R_D": "PREFAILED", "R_E": "CONFIRMED"}
    before = snapshot(client)
    events.settle(0.5)
    announced = len(events.messages)

    if how == "SIGTERM":
        assert fault_manager.stop(signal.SIGTERM) == 0, fault_manager.describe()
    else:
        fault_manager.kill()
    ready = fault_manager.start()
    assert f"faults={len(before['list_all'])}" in ready, ready
    client.wait_until_answering()

    assert snapshot(client) == before
    events.wait_matched()  # the new publisher has matched us: anything re-announced is here now
    events.settle(1.0)
    assert non_sync(events.messages[announced:]) == [], "events re-announced after restart"

    # The debounce continues: R_A needs one more FAILED (-3), R_B five PASSED (-2 -> 3).
    assert client.report("R_A", FAILED, 1, "", "/restart/a")
    assert client.fault("R_A").status == "CONFIRMED"
    for expected in ("CONFIRMED", "CONFIRMED", "CONFIRMED", "CONFIRMED", "HEALED"):
        assert client.report("R_B", PASSED, 0, "", "/restart/b")
        assert client.fault("R_B").status == expected
    expected_events = [("fault_confirmed", "R_A", "CONFIRMED"),
                       *[("fault_updated", "R_B", "CONFIRMED")] * 4,
                       ("fault_cleared", "R_B", "HEALED")]
    events.wait_for_count(announced + 1 + len(expected_events), timeout=10.0)
    events.settle(0.5)
    assert non_sync(events.messages[announced:]) == expected_events

    assert fault_manager.stop(signal.SIGTERM) == 0, fault_manager.describe()
    with FaultLedger.open(fault_manager.url, create=False, upgrade=False) as ledger:
        report = ledger.verify()
    assert report.ok, report.problems


# -- load ------------------------------------------------------------------------------------------
CLIENT_SCRIPT = r'''
"""Load client: reports to /fault_manager/report_fault and writes every answer as JSON.

argv: mode (sequential|burst) client_id count out_path go_path answer_timeout
"""
import json
import os
import sys
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros2_medkit_msgs.srv import ReportFault

def plan(client_id, count):
    """One report per unique source_id; every 25th has an invalid fault_code."""
    reports = []
    for i in range(count):
        source = f"/load/c{client_id}/r{i}"
        if i % 25 == 24:
            reports.append(["LOAD BAD", 0, 1, source])
        else:
            reports.append([f"LOAD_{i % 5}", 1 if i % 3 == 0 else 0, i % 4, source])
    return reports


def main():
    mode, client_id, count, out_path, go_path, answer_timeout = sys.argv[1:7]
    client_id, count, answer_timeout = int(client_id), int(count), float(answer_timeout)
    context = Context()
    rclpy.init(context=context)
    node = Node(f"load_client_{client_id}", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    client = node.create_client(ReportFault, "/fault_manager/report_fault", qos_profile=qos)
    if not client.wait_for_service(timeout_sec=30.0):
        print("report_fault not available", file=sys.stderr)
        sys.exit(3)
    with open(out_path + ".ready", "w"):
        pass
    deadline = time.monotonic() + 60.0
    while not os.path.exists(go_path):
        if time.monotonic() > deadline:
            print("no go signal", file=sys.stderr)
            sys.exit(4)
        time.sleep(0.002)

    reports = plan(client_id, count)
    requests = [ReportFault.Request(fault_code=code, event_type=event_type, severity=severity,
                                    description=f"client {client_id}", source_id=source)
                for code, event_type, severity, source in reports]
    answers = [None] * count
    started = time.monotonic()
    if mode == "burst":
        futures = [client.call_async(request) for request in requests]
        end = time.monotonic() + answer_timeout
        while time.monotonic() < end and not all(f.done() for f in futures):
            executor.spin_once(timeout_sec=0.05)
        for i, future in enumerate(futures):
            if future.done():
                answers[i] = bool(future.result().accepted)
    else:
        for i, request in enumerate(requests):
            future = client.call_async(request)
            end = time.monotonic() + answer_timeout
            while not future.done() and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
            if not future.done():
                client.remove_pending_request(future)
                break
            answers[i] = bool(future.result().accepted)
    elapsed = time.monotonic() - started
    with open(out_path, "w") as out:
        json.dump({"reports": reports, "answers": answers, "elapsed": elapsed}, out)
    node.destroy_node()
    rclpy.shutdown(context=context)


if __name__ == "__main__":
    main()
'''


LOAD_CODES = 5  # the client script reports LOAD_0 .. LOAD_4
SETUP_SOURCE = "/setup/load"


@dataclass(frozen=True)
class Sent:
    fault_code: str
    event_type: int
    severity: int
    source_id: str
    accepted: bool | None  # None: never answered


class LoadClients:
    """Client processes running CLIENT_SCRIPT: started, then released together with ``go``."""

    def __init__(self, directory: Path, mode: str, clients: int, count: int,
                 answer_timeout: float = 60.0) -> None:
        script = directory / "load_client.py"
        script.write_text(CLIENT_SCRIPT, encoding="utf-8")
        self.go_path = directory / f"go-{mode}"
        self.outs = [directory / f"client-{mode}-{i}.json" for i in range(clients)]
        self.logs = [directory / f"client-{mode}-{i}.stderr" for i in range(clients)]
        self.procs: list[subprocess.Popen[bytes]] = []
        for i in range(clients):
            with self.logs[i].open("wb") as log:
                self.procs.append(subprocess.Popen(
                    [sys.executable, str(script), mode, str(i), str(count), str(self.outs[i]),
                     str(self.go_path), str(answer_timeout)],
                    stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=log,
                    cwd=directory))
        try:
            deadline = time.monotonic() + 60.0
            while not all(Path(f"{out}.ready").exists() for out in self.outs):
                crashed = [i for i, p in enumerate(self.procs) if p.poll() is not None]
                assert not crashed, [self.logs[i].read_text(errors="replace") for i in crashed]
                assert time.monotonic() < deadline, "load clients did not find the service"
                time.sleep(0.01)
        except BaseException:
            self.kill()
            raise

    def go(self) -> None:
        self.go_path.touch()

    def kill(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()

    def results(self) -> tuple[list[Sent], float]:
        """Every report with its answer, and the longest client's sending time."""
        try:
            for i, proc in enumerate(self.procs):
                code = proc.wait(timeout=120.0)
                assert code == 0, (
                    f"client {i} exited {code}: {self.logs[i].read_text(errors='replace')}")
        finally:
            self.kill()
        sent: list[Sent] = []
        longest = 0.0
        for out in self.outs:
            data = json.loads(out.read_text(encoding="utf-8"))
            longest = max(longest, float(data["elapsed"]))
            sent.extend(Sent(code, event_type, severity, source, answer)
                        for (code, event_type, severity, source), answer
                        in zip(data["reports"], data["answers"], strict=True))
        return sent, longest


def run_clients(directory: Path, mode: str, clients: int, count: int) -> tuple[list[Sent], float]:
    load = LoadClients(directory, mode, clients, count)
    load.go()
    return load.results()


def check_logged_exactly_once(url: str, sent: list[Sent]) -> None:
    unanswered = [s for s in sent if s.accepted is None]
    assert not unanswered, f"{len(unanswered)} of {len(sent)} requests never answered"
    valid = [s for s in sent if s.fault_code != "LOAD BAD"]
    wrongly_rejected = [s for s in valid if not s.accepted]
    assert not wrongly_rejected, (
        f"{len(wrongly_rejected)} valid reports rejected, e.g. {wrongly_rejected[:3]}")
    assert not [s for s in sent if s.fault_code == "LOAD BAD" and s.accepted]

    with FaultLedger.open(url, create=False, upgrade=False) as ledger:
        records = [r for r in ledger.history(kinds=["fault_reported"])
                   if (r.source_id or "").startswith("/load/")]
        verify = ledger.verify()
        faults = {f.fault_code: f for f in ledger.list_faults(ALL_STATUSES)}
    assert verify.ok, verify.problems
    logged = Counter(r.source_id for r in records)
    duplicated = {source: n for source, n in logged.items() if n > 1}
    assert not duplicated, f"{len(duplicated)} reports logged more than once"
    assert set(logged) == {s.source_id for s in valid}, (
        f"missing from the log: {len({s.source_id for s in valid} - set(logged))}, "
        f"logged but not accepted: {len(set(logged) - {s.source_id for s in valid})}")
    by_source = {s.source_id: s for s in valid}
    for record in records:
        payload = record.payload
        s = by_source[payload["source_id"]]
        assert (payload["fault_code"], payload["event_type"]) == (
            s.fault_code, "FAILED" if s.event_type == FAILED else "PASSED")
        if s.event_type == FAILED:
            assert payload["severity"] == s.severity
    # The projection agrees: every FAILED source is a reporting source of its fault.
    for code in {s.fault_code for s in valid}:
        sources = {s.source_id for s in valid if s.fault_code == code and s.event_type == FAILED}
        sources.add(SETUP_SOURCE)
        assert set(faults[code].reporting_sources) == sources, code
        assert faults[code].occurrence_count == 1


def create_load_faults(client: RosClient) -> None:
    """The faults exist before the clients start: a PASSED for a fault that does not exist yet
    is accepted but not recorded (SPEC §4.2), which would depend on who comes first."""
    for i in range(LOAD_CODES):
        assert client.report(f"LOAD_{i}", FAILED, 0, "setup", SETUP_SOURCE)


def test_four_concurrent_clients_every_accepted_report_logged_once(
        manager: ManagerFactory, client: RosClient, tmp_path: Path) -> None:
    fault_manager = manager()
    create_load_faults(client)
    sent, _ = run_clients(tmp_path, "sequential", clients=4, count=150)
    assert len(sent) == 600
    assert fault_manager.stop(signal.SIGTERM) == 0, fault_manager.describe()
    check_logged_exactly_once(fault_manager.url, sent)


def test_burst_of_4x500_every_request_answered_and_logged_once(
        manager: ManagerFactory, client: RosClient, tmp_path: Path) -> None:
    fault_manager = manager()
    create_load_faults(client)
    sent, longest = run_clients(tmp_path, "burst", clients=4, count=500)
    assert len(sent) == 2000
    assert fault_manager.running, fault_manager.describe()
    assert fault_manager.stop(signal.SIGTERM) == 0, fault_manager.describe()
    check_logged_exactly_once(fault_manager.url, sent)
    print(f"burst 4 x 500: answered within {longest:.2f} s")


def test_kill_9_during_a_burst_loses_no_acknowledged_report(
        manager: ManagerFactory, client: RosClient, tmp_path: Path) -> None:
    """SPEC §3: accepted=true is sent only once the record is durable. Kill the manager in the
    middle of a burst: every acknowledged report is in the log after the restart, once; reports
    never answered may or may not be; the log verifies."""
    fault_manager = manager()
    create_load_faults(client)
    load = LoadClients(tmp_path, "burst", clients=4, count=500, answer_timeout=6.0)
    load.go()
    time.sleep(0.8)
    fault_manager.kill()
    sent, _ = load.results()
    fault_manager.start()
    assert fault_manager.stop(signal.SIGTERM) == 0, fault_manager.describe()

    accepted = {s.source_id for s in sent if s.accepted}
    unanswered = {s.source_id for s in sent if s.accepted is None}
    assert not [s for s in sent if s.accepted is False and s.fault_code != "LOAD BAD"]
    with FaultLedger.open(fault_manager.url, create=False, upgrade=False) as ledger:
        logged = Counter(r.source_id for r in ledger.history(kinds=["fault_reported"])
                         if (r.source_id or "").startswith("/load/"))
        verify = ledger.verify()
    assert verify.ok, verify.problems
    assert accepted <= set(logged), f"{len(accepted - set(logged))} acknowledged reports lost"
    assert set(logged) <= accepted | unanswered
    assert max(logged.values(), default=1) == 1, "a report logged twice"
    print(f"kill -9 mid-burst: {len(accepted)} acknowledged, {len(unanswered)} unanswered, "
          f"{len(logged)} logged")
