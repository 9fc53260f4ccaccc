"""The central's side of store and forward (docs/fleet.md), through the service API: a robot's
records, read verbatim from a real robot log (SQLite), pushed into a central log (SQLite, or a
real PostgreSQL with ``--backend postgresql``)."""

from __future__ import annotations

import dataclasses
import sqlite3
import threading
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import create_engine, text

from faultledger import FaultLedger, Policy
from faultledger.domain.clock import to_ns
from faultledger.domain.fleet import BatchError, PushedRecord
from faultledger.errors import InvalidInputError
from faultledger.service import fleet
from faultledger.service.audit import export_history
from faultledger.store import fleet_log


def robot_log(path: Path, robot_id: str, reports: int) -> str:
    url = f"sqlite:///{path}"
    with FaultLedger.open(url, policy=Policy(), robot_id=robot_id, background=False) as robot:
        for n in range(reports):
            robot.report(f"CODE_{n % 7}", "FAILED" if n % 3 else "PASSED", 1, f"d{n}",
                         f"/{robot_id}")
    return url


def records_of(url: str, after: int = 0) -> tuple[str, str, list[PushedRecord]]:
    with FaultLedger.open(url) as robot:
        identity = robot.identity
        assert identity is not None
        rows = list(export_history(robot, from_seq=after + 1))
    return identity.robot_id, identity.ledger_id, [
        PushedRecord(r.seq, r.event_id, r.kind, r.fault_code, r.source_id, r.payload_json,
                     r.occurred_at_ns, r.recorded_at_ns, r.schema_version, r.hash,
                     r.prev_hash or "") for r in rows]


@pytest.fixture
def central(db_url: str) -> Iterator[fleet.Fleet]:
    with FaultLedger.open(db_url, policy=Policy(), robot_id="central",
                          background=False) as ledger, fleet.Fleet(ledger) as robot_logs:
        yield robot_logs


def batches(records: list[PushedRecord], size: int) -> Iterator[list[PushedRecord]]:
    for start in range(0, len(records), size):
        yield records[start:start + size]


def test_a_pushed_log_is_held_record_for_record_and_hash_for_hash(
        central: fleet.Fleet, tmp_path: Path) -> None:
    robot_id, ledger_id, records = records_of(robot_log(tmp_path / "a.db", "robot-a", 250))
    answers = [central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, part))
               for part in batches(records, 100)]
    assert [a.stored for a in answers] == [100, 100, len(records) - 200]
    assert answers[-1].last_seq == records[-1].seq and answers[-1].last_hash == records[-1].hash
    held_robot, page, last = central.chain_hashes(ledger_id, 0, 10_000)
    assert held_robot == robot_id and last == records[-1].seq
    assert page == [(r.seq, r.hash) for r in records]
    [status] = central.robots()
    assert (status.robot_id, status.ledger_id, status.records) == (robot_id, ledger_id,
                                                                   len(records))


def test_a_batch_sent_again_is_ignored_and_a_gap_is_refused_with_the_held_seq(
        central: fleet.Fleet, tmp_path: Path) -> None:
    robot_id, ledger_id, records = records_of(robot_log(tmp_path / "a.db", "robot-a", 40))
    head = records[-1].seq
    central.push(fleet.PushBatch(robot_id, ledger_id, head, records[:20]))
    again = central.push(fleet.PushBatch(robot_id, ledger_id, head, records[10:30]))
    assert (again.stored, again.ignored, again.last_seq) == (10, 10, 30)
    with pytest.raises(BatchError) as gap:
        central.push(fleet.PushBatch(robot_id, ledger_id, head, records[35:]))
    assert gap.value.code == "chain-gap" and gap.value.last_seq == 30
    empty = central.push(fleet.PushBatch(robot_id, ledger_id, head, []))
    assert (empty.last_seq, empty.stored) == (30, 0)


def test_an_edited_record_is_refused_by_seq_and_nothing_is_stored(
        central: fleet.Fleet, tmp_path: Path) -> None:
    path = tmp_path / "a.db"
    url = robot_log(path, "robot-a", 30)
    robot_id, ledger_id, records = records_of(url)
    with sqlite3.connect(path) as conn:  # an edit on the robot before it was pushed
        # The whole quoted value: a bare d17 can be part of the identity record's ledger_id.
        conn.execute("UPDATE events SET payload = replace(payload, '\"d17\"', '\"dXX\"') "
                     "WHERE payload LIKE '%\"d17\"%'")
    _, _, edited = records_of(url)
    bad = next(r for r in edited if "dXX" in r.payload)
    with pytest.raises(BatchError) as refused:
        central.push(fleet.PushBatch(robot_id, ledger_id, edited[-1].seq, edited))
    assert refused.value.code == "broken-chain" and refused.value.seq == bad.seq
    assert central.robots() == []
    # Pushed first, edited later: the record the central holds differs.
    central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records))
    forged = dataclasses.replace(bad, hash=bad.computed_hash())
    with pytest.raises(BatchError) as differs:
        central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, [forged]))
    assert differs.value.code == "record-differs" and differs.value.seq == bad.seq


def test_a_replaced_robot_database_is_a_second_chain_and_another_robot_id_is_refused(
        central: fleet.Fleet, tmp_path: Path) -> None:
    first = records_of(robot_log(tmp_path / "a.db", "robot-a", 10))
    second = records_of(robot_log(tmp_path / "a-new.db", "robot-a", 5))
    for robot_id, ledger_id, records in (first, second):
        central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records))
    chains = central.robots()
    assert [(c.robot_id, c.ledger_id, c.records) for c in chains] == [
        ("robot-a", first[1], len(first[2])), ("robot-a", second[1], len(second[2]))]
    _, ledger_id, records = first
    with pytest.raises(BatchError) as other:
        central.push(fleet.PushBatch("robot-b", ledger_id, records[-1].seq, records))
    assert other.value.code == "robot-differs"


def test_robots_pushing_concurrently_each_keep_their_whole_chain(
        central: fleet.Fleet, tmp_path: Path) -> None:
    logs = [records_of(robot_log(tmp_path / f"r{n}.db", f"robot-{n}", 120)) for n in range(4)]
    errors: list[BaseException] = []

    def push_all(robot_id: str, ledger_id: str, records: list[PushedRecord]) -> None:
        try:
            for part in batches(records, 7):
                central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, part))
        except BaseException as error:  # reported below
            errors.append(error)

    threads = [threading.Thread(target=push_all, args=log) for log in logs]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    for _, ledger_id, records in logs:
        assert central.chain_hashes(ledger_id, 0, 10_000)[1] == [
            (r.seq, r.hash) for r in records]


def test_lag_is_zero_when_caught_up_and_grows_while_the_robot_is_behind(
        central: fleet.Fleet, tmp_path: Path) -> None:
    robot_id, ledger_id, records = records_of(robot_log(tmp_path / "a.db", "robot-a", 20))
    t0 = records[-1].recorded_at_ns + 10**9
    central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records[:5]),
               now_ns=t0)
    [behind] = central.robots(now_ns=t0 + 60 * 10**9)
    assert behind.lag_seconds >= 60
    central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records[5:]),
               now_ns=t0 + 61 * 10**9)
    [caught_up] = central.robots(now_ns=t0 + 61 * 10**9)
    assert caught_up.lag_seconds == 0


def test_history_of_a_robot_equals_the_robots_own_export_and_verify_names_an_edit(
        central: fleet.Fleet, db_url: str, tmp_path: Path) -> None:
    url = robot_log(tmp_path / "a.db", "robot-a", 80)
    robot_id, ledger_id, records = records_of(url)
    central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records))
    with FaultLedger.open(url) as robot:
        own = list(export_history(robot))
        own_failed = list(export_history(robot, kinds=["fault_reported"], codes=["CODE_[12]"],
                                         from_seq=10))
    held = list(central.history("robot-a"))
    assert [row for _, row in held] == own
    assert {identity for identity, _ in held} == {(robot_id, ledger_id)}
    assert [row for _, row in central.history(
        "robot-a", ledger_id, kinds=["fault_reported"], codes=["CODE_[12]"],
        from_seq=10)] == own_failed
    [check] = central.verify("robot-a")
    assert check.report.ok and check.report.records == len(records)

    [chain] = central.chains("robot-a")
    engine = create_engine(fleet_log.chain_url(db_url, chain.chain_id))
    with engine.begin() as conn:  # someone edits the central's copy
        conn.execute(text("UPDATE events SET payload = replace(payload, 'd33', 'dXX') "
                          "WHERE payload LIKE '%\"d33\"%'"))
    engine.dispose()
    bad = next(r.seq for r in records if '"d33"' in r.payload)
    [check] = central.verify("robot-a")
    assert not check.report.ok and check.report.first_bad_seq == bad
    with pytest.raises(InvalidInputError, match="holds no robot robot-z; it holds robot-a"):
        list(central.history("robot-z"))


def timed_robot_log(path: Path, robot_id: str, seed: int, hours: int = 30) -> str:
    """A robot log over ``hours`` hours of the past: reports, clears, goal outcomes."""
    import random

    rng = random.Random(seed)
    url = f"sqlite:///{path}"
    start = datetime(2026, 11, 20, 0, 0, tzinfo=UTC)
    with FaultLedger.open(url, policy=Policy(confirmation_threshold=-2), robot_id=robot_id,
                          background=False) as robot:
        for n in range(hours * 12):
            at = start + timedelta(minutes=5 * n + rng.randrange(5))
            code = rng.choice(["HW_BASE_EMERGENCY_STOP", "NAV_STUCK", "LIDAR_TIMEOUT"])
            roll = rng.random()
            if roll < 0.08:
                robot.clear(code, actor="test", at=at)
            elif roll < 0.15:
                robot.record_goal_outcome("/navigate", f"g{n}", rng.choice(
                    ["ABORTED", "SUCCEEDED", "CANCELED"]), at=at)
            else:
                robot.report(code, "FAILED" if roll < 0.7 else "PASSED", 2, "", "/base", at=at)
    return url


def figures(row: Any) -> dict[str, Any]:
    found: dict[str, Any] = row.as_dict()
    for name in ("robot", "line", "site", "ledger_id", "complete"):
        found.pop(name, None)
    return found


def test_a_robots_statistics_at_the_central_equal_its_own_figure_for_figure(
        central: fleet.Fleet, tmp_path: Path) -> None:
    urls = {name: timed_robot_log(tmp_path / f"{name}.db", name, seed)
            for seed, name in enumerate(["robot-a", "robot-b"])}
    for url in urls.values():
        robot_id, ledger_id, records = records_of(url)
        central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records))
    since, until = "2026-11-20T00:00:00+00:00", "2026-11-21T06:00:00+00:00"
    as_of = datetime(2026, 11, 22, tzinfo=UTC)
    own = {}
    for name, url in urls.items():
        with FaultLedger.open(url) as robot:
            robot.calendar = central.central.calendar
            own[name] = robot.stats("hour", since, until, as_of=as_of)
            own_by_code = robot.stats("day", since, until, group_by=["code"], as_of=as_of)
    at_central = central.stats("hour", since, until, group_by=["robot"], as_of=as_of)
    for name in urls:
        rows = [row for row in at_central if row.group["robot"] == name]
        assert [figures(row) for row in rows] == [figures(row) for row in own[name]]
        assert all(row.complete for row in rows)
    assert [figures(r) for r in central.stats("day", since, until, group_by=["code"],
                                              robot="robot-b", as_of=as_of)] == [
        figures(r) for r in own_by_code]
    # A line of both robots: counts add up, MTTR weighted by repairs.
    line = central.stats("hour", since, until, group_by=["line"], as_of=as_of,
                         labels={"robot-a": {"line": "L3"}, "robot-b": {"line": "L3"}})
    assert {row.group["line"] for row in line} == {"L3"}
    for row, a, b in zip(line, own["robot-a"], own["robot-b"], strict=True):
        assert row.activations == a.activations + b.activations
        assert row.estops == a.estops + b.estops
        assert row.aborted_goals == a.aborted_goals + b.aborted_goals
        if a.repairs + b.repairs:
            expected = ((a.mttr_seconds or 0) * a.repairs + (b.mttr_seconds or 0) * b.repairs
                        ) / (a.repairs + b.repairs)
            assert row.mttr_seconds == pytest.approx(expected)


def flood_robot_log(path: Path, robot_id: str, codes: int) -> str:
    """``codes`` confirmations in the first ten minutes of 2026-11-20, half of them in the
    first minute's second half (a partial minute for a range starting at 00:00:30)."""
    url = f"sqlite:///{path}"
    start = datetime(2026, 11, 20, 0, 0, tzinfo=UTC)
    with FaultLedger.open(url, policy=Policy(confirmation_threshold=-2), robot_id=robot_id,
                          background=False) as robot:
        for n in range(codes):
            at = (start + timedelta(seconds=31 + n) if n < codes // 2
                  else start + timedelta(minutes=1 + n % 8, seconds=n))
            for repeat in range(3):
                robot.report(f"FLOOD_{n:02d}", "FAILED", 2, "", "/base",
                             at=at + timedelta(milliseconds=repeat))
        robot.report("HW_BASE_EMERGENCY_STOP", "FAILED", 2, "", "/base",
                     at=start + timedelta(seconds=45))
    return url


def test_many_robots_read_at_once_give_each_robots_own_figures_on_any_bounds(
        central: fleet.Fleet, tmp_path: Path) -> None:
    """On PostgreSQL one statement per figure reads every robot's log (``Fleet.stats``): with
    bounds off whole minutes, a flood that only the partial first minute tips over the
    limit, and robots of different sizes, each robot's rows are still its own."""
    urls = {"robot-a": timed_robot_log(tmp_path / "a.db", "robot-a", 3, hours=8),
            "robot-b": flood_robot_log(tmp_path / "b.db", "robot-b", 12),
            "robot-c": flood_robot_log(tmp_path / "c.db", "robot-c", 8)}
    for url in urls.values():
        robot_id, ledger_id, records = records_of(url)
        central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records))
    as_of = datetime(2026, 11, 22, tzinfo=UTC)
    for by, since, until in (("hour", "2026-11-20T00:00:30+00:00", "2026-11-20T07:59:45+00:00"),
                             ("10min", "2026-11-20T00:00:00+00:00", "2026-11-20T02:00:00+00:00"),
                             ("shift", "2026-11-19T22:00:00+00:00", "2026-11-21T06:00:00+00:00")):
        at_central = central.stats(by, since, until, group_by=["robot"], as_of=as_of)
        for name, url in urls.items():
            with FaultLedger.open(url) as robot:
                robot.calendar = central.central.calendar
                own = robot.stats(by, since, until, as_of=as_of)
            rows = [row for row in at_central if row.group["robot"] == name]
            assert [figures(row) for row in rows] == [figures(row) for row in own], (by, name)
    first = central.stats("hour", "2026-11-20T00:00:30+00:00", "2026-11-20T01:00:00+00:00",
                          group_by=["robot"], as_of=as_of)
    floods = {row.group["robot"]: row.flood_windows for row in first}
    estops = {row.group["robot"]: row.estops for row in first}
    assert floods == {"robot-a": 0, "robot-b": 1, "robot-c": 0}  # b: 6 + 6 > 10, c: 4 + 4
    assert estops["robot-b"] == estops["robot-c"] == 1


def test_a_robot_that_pushed_part_of_its_log_has_provisional_periods(
        central: fleet.Fleet, tmp_path: Path) -> None:
    robot_id, ledger_id, records = records_of(robot_log(tmp_path / "a.db", "robot-a", 40))
    cut = len(records) // 2
    central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records[:cut]))
    held_until = records[cut - 1].recorded_at_ns
    now = datetime.now(UTC)
    rows = central.stats("10min", now - timedelta(hours=1), now + timedelta(minutes=20),
                         group_by=["robot"], as_of=now)
    assert {row.complete for row in rows} == {True, False}
    assert all(row.complete is (to_ns(row.period.end) <= held_until) for row in rows)
    assert "complete" in rows[0].as_dict()
    central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records[cut:]))
    caught_up = central.stats("10min", now - timedelta(hours=1), now, group_by=["robot"],
                              as_of=now)
    assert all(row.complete for row in caught_up)


def test_faults_per_robot_are_each_robots_own_list(central: fleet.Fleet, tmp_path: Path) -> None:
    urls = [robot_log(tmp_path / f"{n}.db", f"robot-{n}", 25 + 10 * n) for n in range(2)]
    for url in urls:
        robot_id, ledger_id, records = records_of(url)
        central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records))
    for n, url in enumerate(urls):
        with FaultLedger.open(url) as robot:
            own = robot.list_faults()
        held = central.faults(f"robot-{n}")
        assert [item.fault for item in held] == own and own
    assert {item.robot_id for item in central.faults()} == {"robot-0", "robot-1"}


def test_a_push_is_answered_before_projection_and_every_read_sees_it(
        db_url: str, tmp_path: Path) -> None:
    url = robot_log(tmp_path / "a.db", "robot-a", 60)
    robot_id, ledger_id, records = records_of(url)
    with FaultLedger.open(db_url, policy=Policy(), background=False) as ledger, \
            fleet.Fleet(ledger, quiet=60) as central:
        central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records))
        assert central.behind() == {ledger_id: len(records)}
        with FaultLedger.open(url) as robot:
            own = robot.list_faults()
        assert [item.fault for item in central.faults(robot_id)] == own
        assert central.behind() == {}


def test_a_central_stopped_before_projecting_projects_at_its_next_start(
        db_url: str, tmp_path: Path) -> None:
    url = timed_robot_log(tmp_path / "a.db", "robot-a", 3)
    robot_id, ledger_id, records = records_of(url)
    since, until = "2026-11-20T00:00:00+00:00", "2026-11-21T06:00:00+00:00"
    as_of = datetime(2026, 11, 22, tzinfo=UTC)
    with FaultLedger.open(db_url, policy=Policy(), background=False) as ledger:
        with fleet.Fleet(ledger, quiet=60) as central:
            central.push(fleet.PushBatch(robot_id, ledger_id, records[-1].seq, records))
        with fleet.Fleet(ledger, quiet=60) as central:
            at_central = central.stats("hour", since, until, group_by=["robot"], as_of=as_of)
            [check] = central.verify(robot_id)
        with FaultLedger.open(url) as robot:
            robot.calendar = ledger.calendar
            own = robot.stats("hour", since, until, as_of=as_of)
    assert [figures(row) for row in at_central] == [figures(row) for row in own]
    assert check.report.ok, check.report.problems
