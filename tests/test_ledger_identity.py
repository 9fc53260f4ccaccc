"""Every log records, once, its robot_id and a ledger_id (a ``ledger_identified`` record): the
first writer appends it before its first other record, an older log gets it from its next
writer, a read-only open writes nothing, and an explicit robot_id that is not the recorded one
is refused. History exports carry the identity on every record; verify and /health show it.

Real SQLite files, through the FaultLedger API, the CLI and a real HTTP server."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import re
import socket
import sqlite3
import subprocess
import sys
import uuid
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rich.console import Console
from sqlalchemy import create_engine, text

from faultledger import (
    ConfigError,
    FaultLedger,
    IdentityMismatchError,
    InvalidInputError,
    LedgerIdentity,
    Policy,
    Reason,
)
from faultledger.cli import render
from faultledger.domain.clock import to_ns
from faultledger.domain.events import (
    FaultReported,
    LedgerIdentified,
    LogRecord,
    PolicyChanged,
)
from faultledger.domain.fault import Fault
from faultledger.domain.integrity import GENESIS_HASH
from faultledger.domain.periods import default_calendar
from faultledger.domain.projector import Projector, Transition
from faultledger.domain.statistics import StatsFold
from faultledger.domain.types import EventType
from faultledger.domain.validation import ROBOT_ID_RULE
from faultledger.service.config import Settings, load_settings
from faultledger.service.ledger import default_robot_id
from faultledger.store import event_log, projections
from tests.http.conftest import start_server, write_config
from tests.test_migrations import alembic_on, head, revision_of

CLI = [sys.executable, "-m", "faultledger.cli.main"]
T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)
PREVIOUS_HEAD = "0003_goal_outcomes"


def url(path: Path) -> str:
    return f"sqlite:///{path}"


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=60,
                          check=False, cwd=cwd, stdin=subprocess.DEVNULL)


def stored_rows(path: Path) -> list[tuple[Any, ...]]:
    with contextlib.closing(sqlite3.connect(path)) as conn:
        return conn.execute("SELECT * FROM events ORDER BY seq").fetchall()


def kinds(path: Path) -> list[str]:
    return [str(row[2]) for row in stored_rows(path)]


def identity_rows(path: Path) -> list[tuple[Any, ...]]:
    with contextlib.closing(sqlite3.connect(path)) as conn:
        return conn.execute("SELECT seq, robot_id, ledger_id FROM ledger_identity").fetchall()


OLD_FAULT_COLUMNS = ("fault_code", "severity", "description", "first_occurred_ns",
                     "last_occurred_ns", "last_passed_ns", "occurrence_count", "status",
                     "reporting_sources", "debounce_counter", "last_report_failed")
"""The faults table before Alembic 0007 (the operator's day)."""


def save_old_faults(conn: Any, faults: list[Fault]) -> None:
    """Faults as a schema before 0007 holds them: its columns only."""
    rows = [{key: value for key, value in projections.fault_row(fault).items()
             if key in OLD_FAULT_COLUMNS} for fault in faults]
    if rows:
        conn.execute(text(f"INSERT INTO faults ({', '.join(OLD_FAULT_COLUMNS)}) VALUES "
                          f"({', '.join(':' + c for c in OLD_FAULT_COLUMNS)})"), rows)


def save_old_projections(conn: Any, found: list[Transition], seq: int, head_hash: str) -> None:
    """Transitions and the checkpoint as a schema before 0009 holds them (no index by code:
    the upgrade fills it)."""
    conn.execute(text("INSERT INTO transitions VALUES (:seq, :fault_code, :from_status, "
                      ":to_status, :at_ns, :cause, :source_id)"),
                 [{"seq": t.seq, "fault_code": t.fault_code,
                   "from_status": None if t.from_status is None else t.from_status.value,
                   "to_status": t.to_status.value, "at_ns": t.at_ns, "cause": t.cause,
                   "source_id": t.source_id} for t in found])
    conn.execute(text("INSERT INTO checkpoints VALUES ('projection', :seq, :hash, 1)"),
                 {"seq": seq, "hash": head_hash})


def pre_identity_log(path: Path, reports: int = 3) -> None:
    """A log as faultledger wrote it before identities (schema 0003): a policy and reports,
    appended with their projections in one transaction, no identity record."""
    alembic_on(path, "upgrade", PREVIOUS_HEAD)
    at = to_ns(T0)
    records = [LogRecord(1, str(uuid.uuid4()), PolicyChanged(Policy().to_record()), at, at)]
    records += [LogRecord(i + 2, str(uuid.uuid4()),
                          FaultReported(f"OLD_{i}", EventType.FAILED, 2, "", "/old"),
                          at + i, at + i) for i in range(reports)]
    projector = Projector()
    transitions = projector.apply_all(records)
    engine = create_engine(url(path))
    try:
        with engine.begin() as conn:
            head_hash = event_log.append(conn, records, GENESIS_HASH)
            save_old_projections(conn, transitions, len(records), head_hash)
            save_old_faults(conn, projector.committed())
            # No statistics rows: 0006 (stat_hours) moves their checkpoint back to 0 on
            # upgrade and the next writing open recomputes them from the whole log.
    finally:
        engine.dispose()
    assert revision_of(path) == PREVIOUS_HEAD


def recorded_identity(path: Path) -> LedgerIdentity:
    """The identity as its record says (read with sqlite3, not through faultledger)."""
    found = [json.loads(row[5]) for row in stored_rows(path) if row[2] == "ledger_identified"]
    assert len(found) == 1, found
    return LedgerIdentity(found[0]["robot_id"], found[0]["ledger_id"])


# -- a new log -----------------------------------------------------------------------------------
def test_a_new_log_records_its_identity_once_before_everything_else(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), policy=Policy(), robot_id="amr-07") as ledger:
        assert ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor").seq == 3
        assert ledger.clear("MOTOR_OVERHEAT", actor="op").success
        identity = ledger.identity
    with FaultLedger.open(url(path), policy=Policy(), robot_id="amr-07") as ledger:
        assert ledger.report("LIDAR_TIMEOUT", "FAILED", 1, "", "/lidar").accepted
        assert ledger.identity == identity

    assert kinds(path) == ["ledger_identified", "policy_changed", "fault_reported",
                           "fault_cleared", "fault_reported"]
    assert identity == recorded_identity(path)
    assert identity is not None and identity.robot_id == "amr-07"
    assert uuid.UUID(identity.ledger_id).version == 4
    assert identity_rows(path) == [(1, "amr-07", identity.ledger_id)]


def test_each_new_log_gets_its_own_ledger_id(tmp_path: Path) -> None:
    ids = set()
    for name in ("a.db", "b.db"):
        with FaultLedger.open(url(tmp_path / name), robot_id="amr-07") as ledger:
            assert ledger.record_goal_outcome("/nav", "g1", "SUCCEEDED").seq == 2
            assert ledger.identity is not None
            ids.add(ledger.identity.ledger_id)
    assert len(ids) == 2


def test_an_open_that_writes_nothing_records_no_identity(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
        assert ledger.identity is None
        assert ledger.history() == [] and ledger.verify().ok
        assert ledger.run_timers() == 0  # nothing to confirm: nothing appended
        assert ledger.clear("NOPE", actor="op").reason == Reason.NOT_FOUND
    assert kinds(path) == [] and identity_rows(path) == []


def test_the_record_changes_no_fault_announces_nothing_and_counts_nowhere() -> None:
    projector = Projector(stats=StatsFold())
    effect = projector.apply(LogRecord(1, str(uuid.uuid4()),
                                       LedgerIdentified("amr-07", str(uuid.uuid4())), 5, 5))
    assert (effect.fault, effect.transition, effect.notification) == (None, None, None)
    assert projector.committed() == [] and projector.identity_seq == 1
    assert projector.stats is not None
    output = projector.stats.take()
    assert (output.facts, output.goals, output.started) == ([], [], [])


def test_a_batch_that_does_not_commit_leaves_no_identity() -> None:
    """The writer stages a group commit: rolled back (the commit failed), its identity is
    forgotten, so the next group makes one again; readers never see a staged one."""
    projector = Projector()
    projector.stage()
    projector.apply(LogRecord(1, str(uuid.uuid4()), LedgerIdentified("amr-07", "a"), 5, 5))
    assert (projector.identity, projector.committed_identity) == (
        LedgerIdentity("amr-07", "a"), None)
    projector.rollback()
    assert (projector.identity, projector.committed_identity, projector.identity_seq) == (
        None, None, 0)
    projector.stage()
    projector.apply(LogRecord(1, str(uuid.uuid4()), LedgerIdentified("amr-07", "b"), 5, 5))
    projector.apply(LogRecord(2, str(uuid.uuid4()), LedgerIdentified("other", "c"), 5, 5))
    projector.commit()
    assert (projector.committed_identity, projector.identity_seq,
            projector.ignored_identities) == (LedgerIdentity("amr-07", "b"), 1, [2])


# -- the default robot_id ------------------------------------------------------------------------
def test_without_a_robot_id_a_new_identity_names_the_host(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(socket, "gethostname", lambda: "amr-host-3")
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path)) as ledger:
        assert ledger.report("A", "FAILED", 1, "", "/a").accepted
        assert ledger.identity is not None and ledger.identity.robot_id == "amr-host-3"
    assert recorded_identity(path).robot_id == "amr-host-3"


@pytest.mark.parametrize(("host", "expected"), [
    ("amr-07.factory.local", "amr-07.factory.local"),
    ("my robot/β", "my-robot--"),
    ("-leading", "leading"),
    ("x" * 300, "x" * 128),
    ("ß", "robot"),
])
def test_the_host_name_is_made_a_valid_robot_id(monkeypatch: pytest.MonkeyPatch, host: str,
                                                expected: str) -> None:
    monkeypatch.setattr(socket, "gethostname", lambda: host)
    assert default_robot_id() == expected


def test_a_log_copied_to_another_machine_opens_with_its_own_identity(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
        assert ledger.report("A", "FAILED", 1, "", "/a").accepted
    monkeypatch.setattr(socket, "gethostname", lambda: "laptop-of-auditor")
    with FaultLedger.open(url(path)) as ledger:
        assert ledger.identity is not None and ledger.identity.robot_id == "amr-07"
        assert ledger.verify().ok
        assert ledger.report("B", "FAILED", 1, "", "/b").accepted
    assert recorded_identity(path).robot_id == "amr-07"  # once, never rewritten


# -- another robot's log -------------------------------------------------------------------------
def test_an_explicit_other_robot_id_is_refused_and_nothing_is_written(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), policy=Policy(), robot_id="amr-07") as ledger:
        assert ledger.report("A", "FAILED", 1, "", "/a").accepted
        ledger_id = ledger.identity.ledger_id if ledger.identity else ""
    before = stored_rows(path)

    with pytest.raises(IdentityMismatchError) as refused:
        FaultLedger.open(url(path), policy=Policy(confirmation_threshold=-4),
                         robot_id="amr-08")

    message = str(refused.value)
    assert "'amr-07'" in message and "'amr-08'" in message and ledger_id in message
    assert "nothing was written" in message and "own database" in message
    assert refused.value.reason == Reason.INVALID
    assert stored_rows(path) == before


def test_a_log_identified_by_another_process_after_opening_is_refused_at_the_write(
        tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), robot_id="amr-07") as first, \
            FaultLedger.open(url(path), robot_id="amr-08") as second:
        assert first.report("A", "FAILED", 1, "", "/a").accepted
        refused = second.report("B", "FAILED", 1, "", "/b")
        assert not refused.accepted and refused.reason == Reason.INVALID
        assert "'amr-07'" in refused.message and "'amr-08'" in refused.message
        assert first.report("C", "FAILED", 1, "", "/c").accepted
    assert kinds(path).count("ledger_identified") == 1
    assert recorded_identity(path).robot_id == "amr-07"


@pytest.mark.parametrize("bad", ["", "-amr", "amr 07", "amr/07", "é", "x" * 129, "a\n"])
def test_a_robot_id_outside_the_rule_is_refused_naming_it(tmp_path: Path, bad: str) -> None:
    with pytest.raises(InvalidInputError, match=re.escape(ROBOT_ID_RULE)):
        FaultLedger.open(url(tmp_path / "faults.db"), robot_id=bad)
    assert not (tmp_path / "faults.db").exists()
    with pytest.raises(ValueError, match=re.escape(ROBOT_ID_RULE)):
        Settings.model_validate({"robot_id": bad})


# -- a log written before identities -------------------------------------------------------------
def test_upgrading_from_the_previous_head_keeps_every_record(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    pre_identity_log(path)
    before = stored_rows(path)

    done = run_cli("db", "upgrade", "--db", url(path))

    assert done.returncode == 0, done.stderr
    assert revision_of(path) == head()  # every revision after 0003, 0004_ledger_identity too
    assert stored_rows(path) == before and identity_rows(path) == []
    verified = run_cli("verify", "--db", url(path), "--json")
    assert verified.returncode == 0, verified.stderr
    data = json.loads(verified.stdout)
    assert (data["ok"], data["records"], data["robot_id"], data["ledger_id"]) == (
        True, 4, None, None)


def test_read_only_opens_of_an_older_log_write_no_identity(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    pre_identity_log(path)
    before = stored_rows(path)
    with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
        assert ledger.identity is None
        assert len(ledger.history()) == 4 and ledger.verify().ok
        assert [f.fault_code for f in ledger.all_faults()] == ["OLD_0", "OLD_1", "OLD_2"]
    for command in (["list", "--all"], ["history", "--json"], ["verify"], ["state-at", "2"]):
        done = run_cli(*command, "--db", url(path))
        assert done.returncode == 0, (command, done.stderr)
    assert stored_rows(path) == before


def test_the_next_writer_of_an_older_log_appends_its_identity(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    pre_identity_log(path)
    with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
        assert ledger.report("NEW", "FAILED", 1, "", "/new").seq == 6
        assert ledger.verify().ok
    assert kinds(path) == ["policy_changed", *["fault_reported"] * 3, "ledger_identified",
                           "fault_reported"]
    assert identity_rows(path) == [(5, "amr-07", recorded_identity(path).ledger_id)]


def test_a_serving_writer_identifies_an_older_log_when_it_starts(tmp_path: Path) -> None:
    """Its policy is the recorded one (nothing else to write): the identity alone."""
    path = tmp_path / "faults.db"
    pre_identity_log(path)
    with FaultLedger.open(url(path), policy=Policy(), robot_id="amr-07") as ledger:
        assert ledger.identity == recorded_identity(path)
    assert kinds(path)[4:] == ["ledger_identified"]


def test_exports_of_an_older_log_carry_its_identity_once_it_has_one(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    pre_identity_log(path)
    assert run_cli("db", "upgrade", "--db", url(path)).returncode == 0
    empty = export_jsonl(path)
    assert {(r["robot_id"], r["ledger_id"]) for r in empty} == {(None, None)}
    with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
        assert ledger.report("NEW", "FAILED", 1, "", "/new").accepted
    identity = recorded_identity(path)
    rows = export_jsonl(path)
    assert len(rows) == 6  # the four older records carry it too
    assert {(r["robot_id"], r["ledger_id"]) for r in rows} == {tuple(identity)}


# -- restart, rebuild, verify --------------------------------------------------------------------
def test_the_identity_survives_restart_and_rebuild(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
        assert ledger.report("A", "FAILED", 1, "", "/a").accepted
        identity = ledger.identity
    with FaultLedger.open(url(path)) as ledger:
        assert ledger.identity == identity
        assert ledger.rebuild() == 3
        assert ledger.identity == identity
        assert ledger.verify().ok
    assert identity_rows(path) == [(1, "amr-07", identity.ledger_id if identity else "")]


def test_verify_compares_the_identity_projection_with_a_replay(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
        assert ledger.report("A", "FAILED", 1, "", "/a").accepted
    with contextlib.closing(sqlite3.connect(path)) as conn, conn:
        conn.execute("UPDATE ledger_identity SET robot_id = 'amr-99'")

    with FaultLedger.open(url(path)) as ledger:
        report = ledger.verify()
        assert not report.ok and report.first_bad_seq is None  # the log itself is intact
        assert any("recorded identity (robot_id 'amr-99'" in p and "full replay" in p
                   and "'amr-07'" in p for p in report.problems), report.problems
        ledger.rebuild()
        assert ledger.verify().ok and ledger.identity is not None
        assert ledger.identity.robot_id == "amr-07"


def test_verify_names_a_second_identity_record_which_is_ignored(tmp_path: Path) -> None:
    """No writer writes one: a record appended by something else (its hash chained, as a
    foreign writer would) is named by verify and changes nothing."""
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
        assert ledger.report("A", "FAILED", 1, "", "/a").accepted
        identity = ledger.identity
    engine = create_engine(url(path))
    try:
        with engine.begin() as conn:
            seq, head_hash = event_log.head(conn)
            event_log.append(conn, [LogRecord(seq + 1, str(uuid.uuid4()),
                                              LedgerIdentified("intruder", str(uuid.uuid4())),
                                              5, 5)], head_hash)
    finally:
        engine.dispose()

    with FaultLedger.open(url(path)) as ledger:
        assert ledger.identity == identity
        report = ledger.verify()
    assert not report.ok
    assert report.problems == [f"record {seq + 1} is a second ledger_identified record (the "
                               "log's identity is record 1): no writer writes one; it is "
                               "ignored"]


def test_downgrade_and_upgrade_restore_the_identity_from_the_log(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
        assert ledger.report("A", "FAILED", 1, "", "/a").accepted
        identity = ledger.identity
    alembic_on(path, "downgrade", PREVIOUS_HEAD)
    alembic_on(path, "upgrade", "head")
    assert identity is not None
    assert identity_rows(path) == [(1, identity.robot_id, identity.ledger_id)]
    with FaultLedger.open(url(path)) as ledger:
        assert ledger.identity == identity and ledger.verify().ok


# -- the CLI: config, exports, verify --------------------------------------------------------------
def export_jsonl(path: Path) -> list[dict[str, Any]]:
    done = run_cli("history", "--format", "jsonl", "--db", url(path))
    assert done.returncode == 0, done.stderr
    return [json.loads(line) for line in done.stdout.splitlines()]


def test_config_robot_id_is_recorded_and_a_mismatch_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    first = tmp_path / "first.yaml"
    first.write_text("robot_id: amr-07\n")
    other = tmp_path / "other.yaml"
    other.write_text("robot_id: amr-08\n")

    done = run_cli("report", "A", "FAILED", "--db", url(path), "--config", str(first))
    assert done.returncode == 0, done.stderr
    assert recorded_identity(path).robot_id == "amr-07"
    before = stored_rows(path)

    refused = run_cli("report", "B", "FAILED", "--db", url(path), "--config", str(other))
    assert refused.returncode == 2
    assert "'amr-07'" in refused.stderr and "'amr-08'" in refused.stderr
    assert "Traceback" not in refused.stderr
    assert stored_rows(path) == before
    # A command that only reads opens any robot's log: it records nothing.
    assert run_cli("verify", "--db", url(path), "--config", str(other)).returncode == 0


def test_a_bad_config_robot_id_is_a_located_config_error(tmp_path: Path) -> None:
    config = tmp_path / "bad.yaml"
    config.write_text("robot_id: 'amr 07'\n")
    done = run_cli("report", "A", "FAILED", "--db", url(tmp_path / "f.db"),
                   "--config", str(config))
    assert done.returncode == 2
    assert "robot_id" in done.stderr and "letters, digits, _ . -" in done.stderr
    assert not (tmp_path / "f.db").exists()
    with pytest.raises(ConfigError, match="robot_id"):
        load_settings(config)


def test_exports_carry_the_identity_on_every_record_and_still_verify(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), policy=Policy(), robot_id="amr-07") as ledger:
        for i in range(3):
            assert ledger.report(f"C{i}", "FAILED", 1, "", "/a",
                                 at=T0 + timedelta(seconds=i)).accepted
        identity = ledger.identity
    assert identity is not None

    rows = export_jsonl(path)
    assert [r["kind"] for r in rows][:2] == ["ledger_identified", "policy_changed"]
    assert {(r["robot_id"], r["ledger_id"]) for r in rows} == {tuple(identity)}
    assert rows[0]["payload"] == {"robot_id": "amr-07", "ledger_id": identity.ledger_id}
    assert rows[0]["fault_code"] is None and rows[0]["source_id"] is None

    done = run_cli("history", "--format", "csv", "--db", url(path))
    assert done.returncode == 0, done.stderr
    table = list(csv.DictReader(io.StringIO(done.stdout)))
    assert list(table[0])[-2:] == ["robot_id", "ledger_id"]
    assert {(r["robot_id"], r["ledger_id"]) for r in table} == {tuple(identity)}
    assert [r["hash"] for r in table] == [r["hash"] for r in rows]

    shown = run_cli("history", "--kind", "ledger_identified", "--db", url(path), "--wide")
    assert shown.returncode == 0, shown.stderr
    assert "amr-07" in shown.stdout


def test_an_80_column_history_keeps_the_kind_column_and_breaks_long_kinds(
        tmp_path: Path) -> None:
    """The narrow table shows the robot over the ledger's short id; a kind longer than its
    column is broken after an underscore onto a second line (never an escaped ``\\n``)."""
    with FaultLedger.open(url(tmp_path / "faults.db"), robot_id="amr-07",
                          policy=Policy(confirmation_threshold=-3, auto_confirm_after_sec=1.0),
                          background=False) as ledger:
        assert ledger.report("A", "FAILED", 1, "", "/a", at=T0).accepted
        assert ledger.run_timers(T0 + timedelta(seconds=2)) == 1
        records = ledger.history()
        identity = ledger.identity
    assert identity is not None
    out = Console(width=80, file=io.StringIO(), color_system=None)
    out.print(render.history_table(records, default_calendar(), 80))
    shown = out.file.getvalue()  # type: ignore[attr-defined]
    lines = shown.splitlines()
    assert "kind" in lines[2] and "\\n" not in shown
    assert any("ledger_" in line and "amr-07" in line for line in lines)
    assert any("identified" in line and f"ledger {identity.ledger_id[:8]}…" in line
               for line in lines)
    assert any("fault_confirmed_" in line for line in lines)
    assert any("by_timer" in line for line in lines)


def test_cli_verify_shows_the_identity(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
        assert ledger.report("A", "FAILED", 1, "", "/a").accepted
        identity = ledger.identity
    assert identity is not None

    done = run_cli("verify", "--db", url(path))
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("OK: 3 records")
    assert f"robot_id amr-07, ledger_id {identity.ledger_id}" in done.stdout
    data = json.loads(run_cli("verify", "--json", "--db", url(path)).stdout)
    assert (data["robot_id"], data["ledger_id"]) == tuple(identity)
    segment = json.loads(run_cli("verify", "--json", "--from-seq", "2", "--db",
                                 url(path)).stdout)
    assert (segment["ok"], segment["robot_id"], segment["ledger_id"]) == (True, *identity)


# -- HTTP ----------------------------------------------------------------------------------------
@pytest.fixture
def served(tmp_path: Path) -> Iterator[tuple[Any, Path]]:
    config = write_config(tmp_path / "config.yaml", extra={"robot_id": "amr-07"})
    server = start_server(tmp_path / "faults.db", config=config)
    try:
        yield server, tmp_path / "faults.db"
    finally:
        server.stop()


def test_health_and_history_over_http_show_the_identity(served: tuple[Any, Path]) -> None:
    server, path = served
    health = server.client.get("/health").json()
    identity = recorded_identity(path)  # the serving writer identified the new log at start
    assert (health["robot_id"], health["ledger_id"]) == tuple(identity)
    answer = server.client.post("/api/v1/reports", json={
        "fault_code": "A", "event_type": "FAILED", "severity": 1, "source_id": "/a"})
    assert answer.status_code == 200, answer.text

    page = server.client.get("/api/v1/history").json()
    assert [r["kind"] for r in page["items"]] == ["ledger_identified", "policy_changed",
                                                  "fault_reported"]
    assert {(r["robot_id"], r["ledger_id"]) for r in page["items"]} == {tuple(identity)}
    lines = server.client.get("/api/v1/history", params={"format": "jsonl"}).text.splitlines()
    assert {(json.loads(line)["robot_id"], json.loads(line)["ledger_id"])
            for line in lines} == {tuple(identity)}
    exported = list(csv.DictReader(io.StringIO(
        server.client.get("/api/v1/history", params={"format": "csv"}).text)))
    assert len(exported) == 3
    assert {(r["robot_id"], r["ledger_id"]) for r in exported} == {tuple(identity)}


def test_health_of_a_log_without_identity_says_none(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    pre_identity_log(path)
    assert run_cli("db", "upgrade", "--db", url(path)).returncode == 0
    server = start_server(path, "--read-only", config=write_config(path.with_suffix(".yaml")))
    try:
        health = server.client.get("/health").json()
        assert (health["robot_id"], health["ledger_id"]) == (None, None)
        # Another process identifies the log: the reading server sees it.
        with FaultLedger.open(url(path), robot_id="amr-07") as ledger:
            assert ledger.report("NEW", "FAILED", 1, "", "/new").accepted
        health = server.client.get("/health").json()
        assert (health["robot_id"], health["ledger_id"]) == tuple(recorded_identity(path))
    finally:
        server.stop()


# -- property: any sequence of writers leaves one identity, first among its records ----------------
ROBOTS = [None, "amr-07", "amr-08"]
steps = st.lists(st.tuples(st.sampled_from(["read", "report", "goal", "clear", "timers",
                                            "serve"]),
                           st.sampled_from(ROBOTS)), min_size=1, max_size=10)
_files = iter(range(10**9))


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(plan=steps)
def test_any_writers_leave_one_identity_before_their_records(
        tmp_path: Path, plan: list[tuple[str, str | None]]) -> None:
    """Whatever opens, writes or is refused, in any order: the log's first record is its only
    identity; an explicit robot_id that is not the recorded one writes nothing."""
    path = tmp_path / f"p{next(_files)}.db"
    now = T0
    first_robot: str | None = None
    for action, robot_id in plan:
        before = stored_rows(path) if path.exists() else []
        policy = Policy(confirmation_threshold=-2) if action == "serve" else None
        try:
            ledger = FaultLedger.open(url(path), policy=policy, robot_id=robot_id,
                                      background=False)
        except IdentityMismatchError:
            assert first_robot is not None and robot_id not in (None, first_robot)
            assert stored_rows(path) == before
            continue
        with ledger:
            now += timedelta(seconds=1)
            if action == "report":
                assert ledger.report("A", "FAILED", 1, "", "/a", at=now).accepted
            elif action == "goal":
                assert ledger.record_goal_outcome("/nav", f"g{now.timestamp()}", "ABORTED",
                                                  at=now).accepted
            elif action == "clear":
                ledger.clear("A", actor="op", at=now)
            elif action == "timers":
                ledger.run_timers(now + timedelta(hours=1))
            if first_robot is None and ledger.identity is not None:
                first_robot = ledger.identity.robot_id
                assert first_robot == (robot_id or default_robot_id())
        if action == "read":
            assert stored_rows(path) == before
    recorded = kinds(path)
    if recorded:
        assert recorded[0] == "ledger_identified" and recorded.count("ledger_identified") == 1
        assert recorded_identity(path).robot_id == first_robot
        with FaultLedger.open(url(path)) as ledger:
            assert ledger.verify().ok
