"""Goal outcome records (SPEC §3, §7, §8): each action goal's terminal status is its own record,
once per (action, goal id), so aborts are counted exactly while the action's fault stays
latched. Real SQLite files, the public FaultLedger API and the CLI in a subprocess; no mocks.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import uuid
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faultledger import FaultLedger, GoalOutcomeRequest, Notification, Policy
from faultledger.domain.events import GOAL_OUTCOME_NAMESPACE, GoalOutcome
from faultledger.service.audit import export_history

NAV = "/nav/navigate_to_pose"
T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)
CLI = [sys.executable, "-m", "faultledger.cli.main"]


def url(path: Path) -> str:
    return f"sqlite:///{path}"


@pytest.fixture
def ledger(tmp_path: Path) -> Iterator[FaultLedger]:
    opened = FaultLedger.open(url(tmp_path / "faults.db"), policy=Policy(), background=False)
    yield opened
    opened.close()


def goal_records(ledger: FaultLedger) -> list[GoalOutcome]:
    events = [r.event for r in ledger.history(kinds=["goal_outcome"])]
    assert all(isinstance(e, GoalOutcome) for e in events)
    return events  # type: ignore[return-value]


def test_a_goal_outcome_is_a_record_of_its_own(ledger: FaultLedger) -> None:
    result = ledger.record_goal_outcome(NAV, "9f2c", "ABORTED", "/bt_navigator", at=T0)
    assert result.accepted and not result.duplicate
    assert result.message == f"recorded as seq {result.seq}"
    [record] = ledger.history(kinds=["goal_outcome"])
    assert record.seq == result.seq and record.event_id == result.event_id
    assert record.kind == "goal_outcome" and record.schema_version == 1
    assert record.payload == {"action": NAV, "goal_id": "9f2c", "status": "ABORTED",
                              "server_node": "/bt_navigator"}
    assert record.fault_code is None
    assert record.source_id == "/bt_navigator"
    assert record.occurred_at == T0


def test_the_event_id_is_uuid5_of_action_and_goal_id(ledger: FaultLedger) -> None:
    first = ledger.record_goal_outcome(NAV, "g1", "SUCCEEDED")
    other_action = ledger.record_goal_outcome("/dock", "g1", "SUCCEEDED")
    assert first.event_id == str(uuid.uuid5(GOAL_OUTCOME_NAMESPACE, f"{NAV}\ng1"))
    assert other_action.accepted and other_action.event_id != first.event_id


def test_a_repeat_is_accepted_as_duplicate_and_stores_nothing(tmp_path: Path) -> None:
    path = url(tmp_path / "faults.db")
    with FaultLedger.open(path, background=False) as ledger:
        first = ledger.record_goal_outcome(NAV, "g1", "ABORTED", "/bt_navigator", at=T0)
        head = ledger.last_seq
        again = ledger.record_goal_outcome(NAV, "g1", "ABORTED", "/bt_navigator",
                                           at=T0 + timedelta(seconds=5))
        # Even a different status: the first terminal status of a goal is its outcome.
        changed = ledger.record_goal_outcome(NAV, "g1", "SUCCEEDED")
        assert ledger.last_seq == head
    with FaultLedger.open(path, background=False) as ledger:  # a restarted bridge resends
        restarted = ledger.record_goal_outcome(NAV, "g1", "ABORTED", "/bt_navigator")
        assert ledger.last_seq == head
        assert [g.status for g in goal_records(ledger)] == ["ABORTED"]
        assert ledger.verify().ok
    for repeat in (again, changed, restarted):
        assert repeat.accepted and repeat.duplicate
        assert repeat.seq is None and repeat.event_id == first.event_id
        assert "already recorded" in repeat.message


def test_a_republished_array_in_one_batch_stores_each_goal_once(ledger: FaultLedger) -> None:
    batch = [GoalOutcomeRequest(NAV, "a", "ABORTED", "/bt"),
             GoalOutcomeRequest(NAV, "b", "ABORTED"),
             GoalOutcomeRequest(NAV, "a", "ABORTED", "/bt")]
    results = ledger.record_goal_outcomes(batch)
    assert [(r.accepted, r.duplicate) for r in results] == [(True, False), (True, False),
                                                             (True, True)]
    results = ledger.record_goal_outcomes(batch)
    assert [r.duplicate for r in results] == [True, True, True]
    assert [g.goal_id for g in goal_records(ledger)] == ["a", "b"]


def test_concurrent_senders_of_one_goal_store_it_once(ledger: FaultLedger) -> None:
    """Many threads (sharing group commits) send the outcomes of the same 20 goals."""
    start = threading.Barrier(8)
    answers: list[bool] = []
    lock = threading.Lock()

    def send() -> None:
        start.wait()
        for i in range(20):
            result = ledger.record_goal_outcome(NAV, f"g{i}", "ABORTED", "/bt")
            assert result.accepted, result.message
            with lock:
                answers.append(result.duplicate)

    threads = [threading.Thread(target=send) for _ in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert answers.count(False) == 20 and len(answers) == 160
    assert sorted(g.goal_id for g in goal_records(ledger)) == sorted(f"g{i}" for i in range(20))
    assert sum(row.aborted_goals for row in ledger.stats("hour")) == 20  # the last 24 h


def test_it_changes_no_fault_and_announces_nothing(ledger: FaultLedger) -> None:
    heard: list[Notification] = []
    ledger.subscribe(heard.append)
    assert ledger.report("ACTION_NAV_ABORTED", "FAILED", 2, "", "/bridge", at=T0).accepted
    heard.clear()
    faults, transitions = ledger.all_faults(), ledger.transitions()
    seq = ledger.last_seq
    for i in range(3):
        assert ledger.record_goal_outcome(NAV, f"g{i}", "ABORTED", "/bt",
                                          at=T0 + timedelta(seconds=i + 1)).accepted
    assert heard == []
    assert ledger.all_faults() == faults and ledger.transitions() == transitions
    assert ledger.state_at(seq) == ledger.state_at(ledger.last_seq) == faults
    assert ledger.state_at(datetime.now(UTC)) == faults


def test_it_records_no_policy_before_it(tmp_path: Path) -> None:
    """A goal outcome depends on no debounce policy: the first record of a log after its
    identity may be one, and no policy_changed is written for it (SPEC §3: recorded before a
    record that needs it)."""
    with FaultLedger.open(url(tmp_path / "faults.db"), background=False) as ledger:
        assert ledger.record_goal_outcome(NAV, "g1", "ABORTED").seq == 2
        assert [r.kind for r in ledger.history()] == ["ledger_identified", "goal_outcome"]
        assert ledger.report("X", "FAILED", 1, "", "/x").accepted
        assert [r.kind for r in ledger.history()] == ["ledger_identified", "goal_outcome",
                                                      "policy_changed", "fault_reported"]


def test_code_and_source_filters_treat_it_as_a_record_without_code(
    ledger: FaultLedger
) -> None:
    assert ledger.report("ACTION_NAV_ABORTED", "FAILED", 2, "", "/bt", at=T0).accepted
    assert ledger.record_goal_outcome(NAV, "g1", "ABORTED", "/bt", at=T0).accepted
    assert [r.kind for r in ledger.history(code="ACTION_NAV_ABORTED")] == ["fault_reported"]
    assert [r.kind for r in ledger.history(codes=["*"])] == ["fault_reported"]
    assert [r.kind for r in ledger.history(source="/bt")] == ["fault_reported", "goal_outcome"]
    assert [r.kind for r in ledger.history(since=T0, until=T0 + timedelta(seconds=1))] == [
        "fault_reported", "goal_outcome"]


def test_export_verify_rebuild_and_replay_see_it(tmp_path: Path) -> None:
    path = url(tmp_path / "faults.db")
    with FaultLedger.open(path, policy=Policy(), background=False) as ledger:
        assert ledger.report("ACTION_NAV_ABORTED", "FAILED", 2, "", "/bt", at=T0).accepted
        for i, status in enumerate(("ABORTED", "CANCELED", "SUCCEEDED", "ABORTED")):
            assert ledger.record_goal_outcome(NAV, f"g{i}", status, "/bt",
                                              at=T0 + timedelta(minutes=i)).accepted
        stored = [row for row in export_history(ledger, kinds=["goal_outcome"])]
        assert [json.loads(row.payload_json)["status"] for row in stored] == [
            "ABORTED", "CANCELED", "SUCCEEDED", "ABORTED"]
        assert all(row.fault_code is None and row.source_id == "/bt" for row in stored)
        before = ledger.stats("hour", T0, T0 + timedelta(hours=1), as_of=T0)
        assert ledger.verify().ok
        ledger.rebuild()
        assert ledger.verify().ok
        assert ledger.stats("hour", T0, T0 + timedelta(hours=1), as_of=T0) == before
    assert (before[0].aborted_goals, before[0].canceled_goals, before[0].succeeded_goals) == (
        2, 1, 1)
    done = subprocess.run([*CLI, "history", "--kind", "goal_outcome", "--format", "jsonl",
                           "--db", path], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines() if line.strip()]
    assert [(r["kind"], r["fault_code"], r["payload"]["goal_id"]) for r in lines] == [
        ("goal_outcome", None, f"g{i}") for i in range(4)]
    shown = subprocess.run([*CLI, "history", "--kind", "goal_outcome", "--db", path],
                           capture_output=True, text=True, timeout=60)
    assert shown.returncode == 0, shown.stderr
    assert f"goal g1 of {NAV}: CANCELED" in shown.stdout


@pytest.mark.parametrize(("request_", "message"), [
    (GoalOutcomeRequest("", "g", "ABORTED"), "action cannot be empty"),
    (GoalOutcomeRequest("/a" * 129, "g", "ABORTED"),
     "action exceeds maximum length of 256 (got 258)"),
    (GoalOutcomeRequest("/nav\x00x", "g", "ABORTED"),
     "action contains a NUL character (\\x00) at position 4"),
    (GoalOutcomeRequest("/nav\nx", "g", "ABORTED"),
     "action contains a control character (\\n) at position 4"),
    (GoalOutcomeRequest(7, "g", "ABORTED"), "action must be a string, got int"),  # type: ignore[arg-type]
    (GoalOutcomeRequest(NAV, "", "ABORTED"), "goal_id cannot be empty"),
    (GoalOutcomeRequest(NAV, "g" * 65, "ABORTED"),
     "goal_id exceeds maximum length of 64 (got 65)"),
    (GoalOutcomeRequest(NAV, "g\x1b", "ABORTED"),
     "goal_id contains a control character (\\x1b) at position 1"),
    (GoalOutcomeRequest(NAV, "g", "x"), "status must be SUCCEEDED, ABORTED or CANCELED, got 'x'"),
    (GoalOutcomeRequest(NAV, "g", "aborted"),
     "status must be SUCCEEDED, ABORTED or CANCELED, got 'aborted'"),
    (GoalOutcomeRequest(NAV, "g", 4),  # type: ignore[arg-type]
     "status must be SUCCEEDED, ABORTED or CANCELED, got 4"),
    (GoalOutcomeRequest(NAV, "g", "ABORTED", "/n" * 129),
     "server_node exceeds maximum length of 256 (got 258)"),
    (GoalOutcomeRequest(NAV, "g", "ABORTED", "/n\x00"),
     "server_node contains a NUL character (\\x00) at position 2"),
    (GoalOutcomeRequest(NAV, "g", "ABORTED", at=datetime(2026, 11, 21)),
     "at must be a timezone-aware datetime"),
    (GoalOutcomeRequest(NAV, "g", "ABORTED", at="2026-11-21"),  # type: ignore[arg-type]
     "at must be a timezone-aware datetime, got str"),
])
def test_bad_input_is_refused_with_one_clear_message_and_nothing_stored(
    ledger: FaultLedger, request_: GoalOutcomeRequest, message: str
) -> None:
    head = ledger.last_seq
    good = GoalOutcomeRequest(NAV, "ok", "SUCCEEDED")
    bad, fine = ledger.record_goal_outcomes([request_, good])
    assert not bad.accepted and bad.message.startswith(message), bad.message
    assert bad.seq is None and bad.event_id is None
    assert fine.accepted  # the valid one in the same call is recorded all the same
    assert [g.goal_id for g in goal_records(ledger)] == ["ok"]
    assert ledger.last_seq == head + 1


def test_a_time_outside_the_log_is_refused(ledger: FaultLedger) -> None:
    result = ledger.record_goal_outcome(NAV, "g", "ABORTED",
                                        at=datetime(1969, 12, 31, tzinfo=UTC))
    assert not result.accepted and "outside the times the log can hold" in result.message


def test_a_wrong_request_type_is_refused(ledger: FaultLedger) -> None:
    [result] = ledger.record_goal_outcomes([(NAV, "g", "ABORTED")])  # type: ignore[list-item]
    assert not result.accepted
    assert result.message == "expected a GoalOutcomeRequest, got tuple"


# -- the rule in general ----------------------------------------------------------------------

goal_requests = st.lists(st.builds(
    GoalOutcomeRequest, st.sampled_from((NAV, "/arm/pick", "/dock")),
    st.sampled_from(("g1", "g2", "g3", "g4")),
    st.sampled_from(("SUCCEEDED", "ABORTED", "CANCELED")),
    st.sampled_from(("", "/bt_navigator")),
    st.integers(0, 7200).map(lambda s: T0 + timedelta(seconds=s))), min_size=1, max_size=25)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(batches=st.lists(goal_requests, min_size=1, max_size=4))
def test_each_goal_is_stored_once_with_its_first_outcome_and_counted_once(
    batches: list[list[GoalOutcomeRequest]], tmp_path_factory: pytest.TempPathFactory
) -> None:
    path = url(tmp_path_factory.mktemp("goals") / "faults.db")
    first: dict[tuple[str, str], GoalOutcomeRequest] = {}
    with FaultLedger.open(path, background=False) as ledger:
        for batch in batches:
            results = ledger.record_goal_outcomes(batch)
            for request, result in zip(batch, results, strict=True):
                key = (request.action, request.goal_id)
                assert result.accepted and result.duplicate == (key in first)
                first.setdefault(key, request)
        stored = goal_records(ledger)
        assert [(g.action, g.goal_id, g.status, g.server_node) for g in stored] == [
            (r.action, r.goal_id, r.status, r.server_node) for r in first.values()]
        rows = ledger.stats("day", T0, T0 + timedelta(hours=3), as_of=T0)
        for status, figure in (("ABORTED", "aborted_goals"), ("CANCELED", "canceled_goals"),
                               ("SUCCEEDED", "succeeded_goals")):
            assert sum(getattr(row, figure) for row in rows) == sum(
                r.status == status for r in first.values())
        assert ledger.verify().ok
