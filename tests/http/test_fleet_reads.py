"""A fleet central's reads over HTTP (docs/http.md, "Fleet"): a robot's faults as the central
holds them, statistics per robot, line and site with provisional rows marked, through a real
`faultledger http` central that robots pushed to over HTTP; line labels through the app built
in-process with a Context carrying them (the config wiring of ``fleet.robots`` is not in
`faultledger http` yet)."""

from __future__ import annotations

import contextlib
import csv
import io
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import httpx
import pytest

from faultledger import FaultLedger, Policy
from faultledger.domain.types import FaultStatus
from faultledger.http import medkit
from faultledger.http.server import HttpServer
from faultledger.service.config import HttpSettings
from tests.http.fleet_scenario import ESTOP, OWN_FAULT, Fleet, start_fleet, write_log
from tests.http.test_fleet_api import PUSH, body
from tests.test_fleet_central import records_of


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Fleet]:
    started = start_fleet(tmp_path_factory.mktemp("fleet-reads"))
    yield started
    started.server.stop()


def get(fleet: Fleet, path: str, **params: Any) -> Any:
    answer = fleet.server.client.get(path, params=params)
    assert answer.status_code == 200, answer.text
    return answer.json()


def test_a_robots_faults_are_its_own_list_with_robot_and_ledger(fleet: Fleet) -> None:
    with FaultLedger.open(fleet.urls["robot-a"]) as robot:
        own = robot.all_faults()
    held = get(fleet, "/api/v1/faults", robot="robot-a", status="all")
    expected = medkit.fault_list(own)
    for item in expected["items"]:
        item.update(robot_id="robot-a", ledger_id=fleet.ledger_ids["robot-a"])
    assert held == expected
    assert {i["fault_code"] for i in held["items"]} == {ESTOP, "NAV_STUCK", "LIDAR_TIMEOUT"}
    # The status groups as ever: by default PREFAILED and CONFIRMED (the e-stop healed).
    active = get(fleet, "/api/v1/faults", robot="robot-a")
    assert [i["fault_code"] for i in active["items"]] == ["LIDAR_TIMEOUT", "NAV_STUCK"]
    # robot-b: only what it pushed (the gripper jam, not the later presses).
    pushed = get(fleet, "/api/v1/faults", robot="robot-b", status="confirmed")
    assert [(i["fault_code"], i["ledger_id"]) for i in pushed["items"]] == [
        ("GRIPPER_JAM", fleet.ledger_ids["robot-b"])]


def test_without_robot_the_list_is_the_central_own(fleet: Fleet) -> None:
    answer = fleet.server.client.get("/api/v1/faults")
    assert answer.headers["etag"].endswith('-default"')
    assert [i["fault_code"] for i in answer.json()["items"]] == [OWN_FAULT]
    assert "robot_id" not in answer.json()["items"][0]


def test_an_unknown_robot_is_404_naming_the_robots_held(fleet: Fleet) -> None:
    for path in ("/api/v1/faults", "/api/v1/stats"):
        answer = fleet.server.client.get(path, params={"robot": "robot-z"})
        assert answer.status_code == 404, answer.text
        assert answer.json()["reason"] == "not_found"
        assert ("the central holds no robot robot-z; it holds robot-a, robot-b"
                in answer.json()["message"])
        bad = fleet.server.client.get(path, params={"robot": "robot z!"})
        assert bad.status_code == 400 and "robot_id must be" in bad.json()["message"]


def by_robot(rows: list[dict[str, Any]], robot: str, shift: str) -> dict[str, Any]:
    [found] = [r for r in rows if r["robot"] == robot and r["period"] == shift]
    return found


def test_stats_per_robot_say_which_rows_are_provisional(fleet: Fleet) -> None:
    answer = get(fleet, "/api/v1/stats", by="shift", since=fleet.previous.id,
                 group_by="robot")
    rows, as_of = answer["items"], answer["as_of"]
    assert [r["period"] for r in rows] == [fleet.previous.id] * 2 + [fleet.current.id] * 2
    previous_a = by_robot(rows, "robot-a", fleet.previous.id)
    assert (previous_a["estops"], previous_a["aborted_goals"], previous_a["complete"]) == (
        3, 2, True)
    current_a = by_robot(rows, "robot-a", fleet.current.id)
    assert (current_a["estops"], current_a["aborted_goals"]) == (2, 1)
    # The current shift ends at as_of (just after: what happened at as_of counts), one
    # moment for every log.
    [end] = {datetime.fromisoformat(r["end"]) for r in rows if r["period"] == fleet.current.id}
    assert timedelta(0) <= end - datetime.fromisoformat(as_of) <= timedelta(microseconds=1)
    previous_b = by_robot(rows, "robot-b", fleet.previous.id)
    assert (previous_b["estops"], previous_b["complete"]) == (1, False)  # 2 more not pushed
    assert by_robot(rows, "robot-b", fleet.current.id)["complete"] is False
    # The same figures as robot-a computes itself with the central's calendar.
    with FaultLedger.open(fleet.urls["robot-a"]) as robot:
        robot.calendar = fleet.calendar
        [own] = robot.stats("shift", fleet.previous.start, fleet.previous.end)
    assert {k: previous_a[k] for k in own.as_dict()} == own.as_dict()

    one = get(fleet, "/api/v1/stats", by="shift", since=fleet.previous.id, robot="robot-b")
    assert [(r["period"], r["complete"]) for r in one["items"]] == [
        (fleet.previous.id, False), (fleet.current.id, False)]
    assert "robot" not in one["items"][0]


def test_stats_without_fleet_parameters_are_the_central_own(fleet: Fleet) -> None:
    answer = get(fleet, "/api/v1/stats", by="shift", since=fleet.previous.id)
    assert set(answer) == {"items"}
    assert all("complete" not in r and "robot" not in r for r in answer["items"])
    assert sum(r["estops"] for r in answer["items"]) == 0


def test_stats_csv_has_robot_and_complete_columns(fleet: Fleet) -> None:
    answer = fleet.server.client.get("/api/v1/stats", params={
        "by": "shift", "since": fleet.previous.id, "group_by": "robot", "format": "csv"})
    assert answer.status_code == 200 and answer.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(answer.text)))
    assert {(r["robot"], r["period"], r["complete"]) for r in rows} == {
        ("robot-a", fleet.previous.id, "True"), ("robot-a", fleet.current.id, "False"),
        ("robot-b", fleet.previous.id, "False"), ("robot-b", fleet.current.id, "False")}


def test_fleet_group_keys_are_checked_and_the_budget_is_shared(fleet: Fleet) -> None:
    bogus = fleet.server.client.get("/api/v1/stats", params={"group_by": ["robot", "bogus"]})
    assert bogus.status_code == 400
    assert "code, source, severity, action, robot, line, site" in bogus.json()["message"]
    twice = fleet.server.client.get("/api/v1/stats", params={"group_by": ["robot", "robot"]})
    assert twice.status_code == 400
    # 5,760 periods of 10 minutes per log: within the 10,000 of one log, not of two.
    now = datetime.now(UTC)
    wide = fleet.server.client.get("/api/v1/stats", params={
        "by": "10min", "since": (now - timedelta(days=40)).isoformat(), "group_by": "robot"})
    assert wide.status_code == 400, wide.text
    assert "(http.max_stats_rows 10,000 shared by 2 robot logs)" in wide.json()["message"]


# -- line and site labels: the app in-process, with a Context that carries them -------------
IN_PROCESS = pytest.mark.filterwarnings("ignore::hypothesis.errors.HypothesisWarning")
"""HttpServer.start collects garbage, which makes Hypothesis warn about the random generator
trio (loaded by anyio's pytest plugin) registered: nothing of this test's."""


@contextlib.contextmanager
def in_process(directory: Path, labels: dict[str, dict[str, str]] | None = None
               ) -> Iterator[httpx.Client]:
    """A central served in this process (the app of `faultledger http`) whose Context has
    ``labels`` as its ``fleet_labels``."""
    with FaultLedger.open(f"sqlite:///{directory / 'central.db'}", policy=Policy(),
                          robot_id="central", background=False) as ledger:
        server = HttpServer(ledger, HttpSettings(tokens_file=None), ledger.calendar,
                            "127.0.0.1:0")
        server.app.state.context.fleet_labels = labels or {}
        server.start()
        try:
            with httpx.Client(base_url=server.url, timeout=30) as client:
                yield client
        finally:
            server.stop()


@IN_PROCESS
def test_group_by_line_merges_the_robots_of_a_line(tmp_path: Path) -> None:
    start = datetime.now(UTC).replace(minute=0, second=0, microsecond=0) - timedelta(hours=3)
    urls = {name: write_log(tmp_path / f"{name}.db", name, [
        (start + timedelta(minutes=10 + 37 * n + offset), what)
        for n, what in enumerate(["estop", "aborted", "estop", "NAV_STUCK"])])
        for offset, name in enumerate(["robot-a", "robot-b", "robot-c"])}
    labels = {"robot-a": {"line": "L3", "site": "Leipzig"},
              "robot-b": {"line": "L3", "site": "Leipzig"},
              "robot-c": {"line": "L4", "site": "Leipzig"}}
    with in_process(tmp_path, labels) as client:
        for url in urls.values():
            robot_id, ledger_id, records = records_of(url)
            pushed = client.post(PUSH, json=body(robot_id, ledger_id, records,
                                                 records[-1].seq))
            assert pushed.status_code == 200, pushed.text
        params = {"by": "hour", "since": start.isoformat(), "group_by": "line"}
        lines = client.get("/api/v1/stats", params=params).json()["items"]
        per_robot = client.get("/api/v1/stats", params={
            **params, "group_by": ["robot", "line", "site"]}).json()["items"]
        text = client.get("/api/v1/stats", params={**params, "format": "csv"}).text
    assert {r["line"] for r in lines} == {"L3", "L4"}
    for line, robots in (("L3", {"robot-a", "robot-b"}), ("L4", {"robot-c"})):
        merged = [r for r in lines if r["line"] == line]
        parts = [r for r in per_robot if r["robot"] in robots]
        assert sum(r["estops"] for r in merged) == sum(r["estops"] for r in parts) == \
            2 * len(robots)
        assert sum(r["aborted_goals"] for r in merged) == len(robots)
    assert {(r["robot"], r["line"], r["site"]) for r in per_robot} == {
        ("robot-a", "L3", "Leipzig"), ("robot-b", "L3", "Leipzig"), ("robot-c", "L4", "Leipzig")}
    assert text.splitlines()[0].startswith("period,period_name,production_day,start,end,line,")
    assert text.splitlines()[0].endswith(",complete")


@IN_PROCESS
def test_a_replaced_robot_database_has_its_own_rows_and_faults(tmp_path: Path) -> None:
    start = datetime.now(UTC) - timedelta(hours=2)
    old = write_log(tmp_path / "old.db", "robot-a", [(start, "estop"), (start, "NAV_STUCK")])
    new = write_log(tmp_path / "new.db", "robot-a", [(start + timedelta(hours=1), "estop")])
    with in_process(tmp_path) as client:
        ids = []
        for url in (old, new):
            robot_id, ledger_id, records = records_of(url)
            ids.append(ledger_id)
            assert client.post(PUSH, json=body(robot_id, ledger_id, records,
                                               records[-1].seq)).status_code == 200
        faults = client.get("/api/v1/faults", params={"robot": "robot-a",
                                                      "status": "all"}).json()["items"]
        params = {"by": "day", "since": (start - timedelta(days=1)).isoformat(),
                  "group_by": "robot", "format": "csv"}
        rows = list(csv.DictReader(io.StringIO(client.get("/api/v1/stats",
                                                          params=params).text)))
    assert [(f["fault_code"], f["ledger_id"]) for f in faults] == [
        (ESTOP, ids[0]), ("NAV_STUCK", ids[0]), (ESTOP, ids[1])]
    assert all(f["status"] in {s.value for s in FaultStatus} for f in faults)
    assert {r["ledger_id"] for r in rows} == set(ids)
    assert sum(int(r["estops"]) for r in rows) == 2
