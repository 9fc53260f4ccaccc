"""SPEC §9: databases that cannot serve (not a database, read-only, from a newer schema,
locked) and bad CLI input (non-UTF-8 arguments, bad config files) get a clear, specific
message and a non-success status; nothing is written; the CLI never shows a traceback.

Real SQLite files in tmp_path, the CLI as a real subprocess (``python -m faultledger.cli.main``).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from faultledger import FaultLedger
from faultledger.errors import (
    NotADatabaseError,
    SchemaTooNewError,
    StoreError,
)
from faultledger.store.database import BUSY_TIMEOUT_MS

CLI = [sys.executable, "-m", "faultledger.cli.main"]
FUTURE = "9999_future"
NOBODY = 65534


def run_cli(*args: str | bytes, user: int | None = None) -> subprocess.CompletedProcess[str]:
    """Run the CLI; stdout/stderr decoded leniently (an error may echo undecodable input)."""
    done = subprocess.run([*CLI, *args], capture_output=True, timeout=60, user=user,
                          group=user, cwd="/" if user is not None else None)
    return subprocess.CompletedProcess(
        done.args, done.returncode, done.stdout.decode("utf-8", "replace"),
        done.stderr.decode("utf-8", "replace"))


def assert_clean_error(done: subprocess.CompletedProcess[str], *words: str) -> None:
    """Non-zero exit, no traceback, the words in stderr."""
    assert done.returncode != 0, (done.stdout, done.stderr)
    assert "Traceback" not in done.stderr, done.stderr
    for word in words:
        assert word in done.stderr, done.stderr


def url(path: Path) -> str:
    return f"sqlite:///{path}"


def make_ledger_file(path: Path) -> int:
    """A normal database with two faults; returns the log length."""
    with FaultLedger.open(url(path)) as ledger:
        assert ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "hot", "/motor").accepted
        assert ledger.report("LIDAR_TIMEOUT", "FAILED", 1, "", "/sensors/lidar").accepted
        return ledger.last_seq


def log_length(path: Path) -> int:
    with FaultLedger.open(url(path)) as ledger:
        return len(ledger.history())


def events_in_file(path: Path) -> int:
    with contextlib.closing(sqlite3.connect(path)) as conn:
        return int(conn.execute("SELECT COUNT(*) FROM events").fetchone()[0])


# -- a file that is not a database ---------------------------------------------------------------
@pytest.fixture
def not_a_database(tmp_path: Path) -> Path:
    path = tmp_path / "faults.db"
    path.write_bytes(os.urandom(16384))
    return path


def test_open_of_random_bytes_raises_store_error(not_a_database: Path) -> None:
    before = not_a_database.read_bytes()
    with pytest.raises(StoreError) as caught:
        FaultLedger.open(url(not_a_database))
    assert isinstance(caught.value, NotADatabaseError)
    assert "not a faultledger database" in str(caught.value)
    assert not_a_database.read_bytes() == before


@pytest.mark.parametrize("command", [["list"], ["report", "MOTOR_OVERHEAT", "FAILED"],
                                     ["db", "current"]], ids=["list", "report", "db-current"])
def test_cli_on_random_bytes_prints_one_line_error(not_a_database: Path,
                                                   command: list[str]) -> None:
    before = not_a_database.read_bytes()
    done = run_cli(*command, "--db", url(not_a_database))
    assert_clean_error(done, "not a faultledger database")
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not_a_database.read_bytes() == before


EMPTY_FILE = "is an empty file (0 bytes), not a faultledger database; to start a new log, " \
             "delete it or name another path"


def test_open_of_an_empty_file_is_refused_and_writes_nothing(tmp_path: Path) -> None:
    """A 0-byte file (a truncated copy, `touch`) would silently become a new, empty log."""
    path = tmp_path / "faults.db"
    path.touch()
    with pytest.raises(NotADatabaseError) as caught:
        FaultLedger.open(url(path))
    assert str(caught.value) == f"{path} {EMPTY_FILE}"
    assert path.stat().st_size == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["faults.db"]


@pytest.mark.parametrize("command", [["report", "MOTOR_OVERHEAT", "FAILED"], ["list"],
                                     ["db", "current"], ["db", "upgrade"], ["verify"]],
                         ids=["report", "list", "db-current", "db-upgrade", "verify"])
def test_cli_on_an_empty_file_exits_2_saying_how_to_start_a_new_log(tmp_path: Path,
                                                                     command: list[str]) -> None:
    path = tmp_path / "faults.db"
    path.touch()
    done = run_cli(*command, "--db", url(path))
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert_clean_error(done, EMPTY_FILE)
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert path.stat().st_size == 0


def _open_after(barrier: Any, url_: str, answers: Any) -> None:
    barrier.wait()
    try:
        FaultLedger.open(url_).close()
        answers.put("ok")
    except Exception as error:  # reported to the test, which names it
        answers.put(f"{type(error).__name__}: {error}")


def test_a_new_database_is_never_an_empty_file_another_process_could_see(tmp_path: Path
                                                                         ) -> None:
    """faultledger creates a database under a temporary name and links it in place with
    SQLite's header written, so a process opening the path at that moment never finds the
    0-byte file the check above refuses (with the file created empty first, 4 to 7 of 8
    processes released together were refused). Eight writers creating one database at once
    may still give up "locked" waiting for each other's migration: not this check."""
    path = tmp_path / "new.db"
    context = multiprocessing.get_context("fork")
    barrier, answers = context.Barrier(8), context.Queue()
    processes = [context.Process(target=_open_after, args=(barrier, url(path), answers))
                 for _ in range(8)]
    for process in processes:
        process.start()
    found = [answers.get(timeout=60) for _ in processes]
    for process in processes:
        process.join(10)
    assert not [a for a in found if "empty file" in a], found
    assert "ok" in found, found
    assert path.stat().st_mode & 0o777 == 0o600
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


# -- read-only databases -------------------------------------------------------------------------
def read_only_url(path: Path) -> str:
    return f"sqlite:///file:{path}?mode=ro&uri=true"


def test_read_only_database_serves_reads(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    length = make_ledger_file(path)
    with FaultLedger.open(read_only_url(path)) as ledger:
        assert [f.fault_code for f in ledger.list_faults()] == ["LIDAR_TIMEOUT", "MOTOR_OVERHEAT"]
        assert len(ledger.history()) == length
        assert ledger.verify().ok


def test_read_only_database_refuses_report_and_writes_nothing(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    length = make_ledger_file(path)
    with FaultLedger.open(read_only_url(path)) as ledger:
        before = ledger.list_faults(statuses=["CONFIRMED", "PREFAILED", "CLEARED"])
        result = ledger.report("ESTOP", "FAILED", 3, "", "/base")
        cleared = ledger.clear("MOTOR_OVERHEAT", actor="test:alice")
        assert not result.accepted
        assert "read-only" in result.message
        assert not cleared.success and "read-only" in cleared.message
        # the refused writes did not leak into the served state either
        assert ledger.list_faults(statuses=["CONFIRMED", "PREFAILED", "CLEARED"]) == before
        assert ledger.get_fault("ESTOP") is None
    assert log_length(path) == length


def test_cli_report_on_read_only_database_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    length = make_ledger_file(path)
    done = run_cli("report", "ESTOP", "FAILED", "--db", read_only_url(path))
    assert_clean_error(done, "read-only")
    assert done.returncode == 1
    assert log_length(path) == length


@contextlib.contextmanager
def immutable(path: Path) -> Iterator[None]:
    """chattr +i: not even root may write the file."""
    done = subprocess.run(["chattr", "+i", str(path)], capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot make the file immutable here: {done.stderr.strip()}")
    try:
        yield
    finally:
        subprocess.run(["chattr", "-i", str(path)], check=True)


@pytest.mark.skipif(os.geteuid() != 0, reason="chattr +i needs root")
def test_immutable_file_serves_reads_and_refuses_reports(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    length = make_ledger_file(path)
    with immutable(path), FaultLedger.open(url(path)) as ledger:
        assert len(ledger.list_faults()) == 2
        result = ledger.report("ESTOP", "FAILED", 3, "", "/base")
        assert not result.accepted
        assert "read-only" in result.message
    assert log_length(path) == length


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to run the CLI as another user")
def test_file_owned_by_another_user_serves_reads_and_refuses_reports(
        tmp_path: Path, tmp_path_factory: pytest.TempPathFactory) -> None:
    try:
        probe = subprocess.run([*CLI, "--help"], capture_output=True, text=True, user=NOBODY,
                               group=NOBODY, cwd="/", timeout=60)
    except OSError as error:
        pytest.skip(f"user nobody cannot run this interpreter: {error}")
    if probe.returncode != 0:
        pytest.skip("user nobody cannot run this interpreter/venv: "
                    f"{(probe.stderr.strip().splitlines() or [''])[-1]}")
    shared = tmp_path / "shared"
    shared.mkdir()
    path = shared / "faults.db"
    length = make_ledger_file(path)
    # root owns the file (0644) and its directory (0755): nobody may read, not write
    top = tmp_path_factory.getbasetemp().parent
    for directory in [shared, *shared.parents]:
        directory.chmod(directory.stat().st_mode | 0o055)
        if directory == top:
            break
    path.chmod(0o644)
    listing = run_cli("list", "--db", url(path), user=NOBODY)
    assert listing.returncode == 0, listing.stderr
    assert "MOTOR_OVERHEAT" in listing.stdout
    done = run_cli("report", "ESTOP", "FAILED", "--db", url(path), user=NOBODY)
    assert_clean_error(done, "read-only")
    assert log_length(path) == length


# -- a newer schema revision ---------------------------------------------------------------------
def make_future_file(path: Path) -> int:
    length = make_ledger_file(path)
    with contextlib.closing(sqlite3.connect(path)) as conn, conn:
        conn.execute("UPDATE alembic_version SET version_num = ?", (FUTURE,))
    return length


def alembic_version(path: Path) -> str:
    with contextlib.closing(sqlite3.connect(path)) as conn:
        return str(conn.execute("SELECT version_num FROM alembic_version").fetchone()[0])


def test_open_of_newer_schema_raises_schema_too_new(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    length = make_future_file(path)
    with pytest.raises(SchemaTooNewError, match=FUTURE):
        FaultLedger.open(url(path))
    assert alembic_version(path) == FUTURE
    assert events_in_file(path) == length


@pytest.mark.parametrize("command", [["list"], ["report", "ESTOP", "FAILED"],
                                     ["db", "upgrade"]], ids=["list", "report", "db-upgrade"])
def test_cli_on_newer_schema_exits_nonzero_naming_the_revision(tmp_path: Path,
                                                               command: list[str]) -> None:
    path = tmp_path / "faults.db"
    length = make_future_file(path)
    done = run_cli(*command, "--db", url(path))
    assert_clean_error(done, FUTURE, "newer")
    assert alembic_version(path) == FUTURE
    assert events_in_file(path) == length


def test_db_current_says_the_schema_is_newer(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    make_future_file(path)
    done = run_cli("db", "current", "--db", url(path))
    assert_clean_error(done, FUTURE, "newer")


def test_cli_error_for_newer_schema_is_one_line_for_a_long_path(tmp_path: Path) -> None:
    """An operator's deployment path is often long; the message must not be hard-wrapped."""
    path = tmp_path / "var" / "lib" / "faultledger" / "fleet-north" / "line-3" / "faults.db"
    path.parent.mkdir(parents=True)
    make_future_file(path)
    done = run_cli("list", "--db", url(path))
    assert_clean_error(done, FUTURE)
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


# -- a locked database ---------------------------------------------------------------------------
@contextlib.contextmanager
def write_locked(path: Path) -> Iterator[sqlite3.Connection]:
    """Another connection holding the write lock (BEGIN EXCLUSIVE) until the block ends."""
    conn = sqlite3.connect(path, isolation_level=None, timeout=0, check_same_thread=False)
    try:
        conn.execute("BEGIN EXCLUSIVE")
        yield conn
        conn.execute("ROLLBACK")
    finally:
        conn.close()


BUSY_S = BUSY_TIMEOUT_MS / 1000


def test_locked_database_refuses_report_with_locked_message_after_busy_timeout(
        tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    length = make_ledger_file(path)
    with FaultLedger.open(url(path)) as ledger, write_locked(path):
        started = time.monotonic()
        result = ledger.report("ESTOP", "FAILED", 3, "", "/base")
        waited = time.monotonic() - started
        assert not result.accepted
        assert "locked" in result.message
        assert BUSY_S - 0.5 <= waited <= BUSY_S + 2.0
        assert len(ledger.history()) == length  # reads are served while locked (WAL)
    assert log_length(path) == length


def test_ledger_keeps_working_after_the_lock_is_released(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    length = make_ledger_file(path)
    with FaultLedger.open(url(path)) as ledger:
        with write_locked(path):
            refused = ledger.report("ESTOP", "FAILED", 3, "refused", "/base")
        assert not refused.accepted
        accepted = ledger.report("ESTOP", "FAILED", 3, "accepted", "/base")
        assert accepted.accepted and accepted.seq == length + 1, accepted.message
        fault = ledger.get_fault("ESTOP")
        assert fault is not None and fault.description == "accepted"
        assert fault.occurrence_count == 1
        report = ledger.verify()
        assert report.ok, report.problems
    assert log_length(path) == length + 1


def test_lock_released_while_waiting_lets_the_report_through(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    length = make_ledger_file(path)
    with FaultLedger.open(url(path)) as ledger, write_locked(path) as holder:
        release = threading.Timer(0.5, holder.execute, ("ROLLBACK",))
        release.start()
        result = ledger.report("ESTOP", "FAILED", 3, "", "/base")
        release.join()
        holder.execute("BEGIN")  # write_locked ends with ROLLBACK
        assert result.accepted, result.message
    assert log_length(path) == length + 1


def test_cli_report_on_locked_database_is_rejected_without_traceback(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    length = make_ledger_file(path)
    with write_locked(path):
        done = run_cli("report", "ESTOP", "FAILED", "--db", url(path))
    assert_clean_error(done, "locked")
    assert done.returncode == 1
    assert log_length(path) == length


# -- non-UTF-8 arguments -------------------------------------------------------------------------
@pytest.mark.parametrize(("option", "field"), [("--description", "description"),
                                              ("--source", "source_id")])
def test_cli_rejects_non_utf8_argument_and_stores_nothing(tmp_path: Path, option: str,
                                                          field: str) -> None:
    path = tmp_path / "faults.db"
    length = make_ledger_file(path)
    done = run_cli("report", "MOTOR_OVERHEAT", "FAILED", option.encode(), b"bad \xff\xfe text",
                   "--db", url(path))
    assert_clean_error(done, field, "UTF-8")
    assert done.returncode == 1
    assert log_length(path) == length


# -- bad configuration files ---------------------------------------------------------------------
CONFIGS = {
    "invalid-yaml": ("policy:\n  healing_threshold: 3\n   confirmation_threshold: -1\n",
                     "line 3"),
    "unknown-key": ("policy:\n  healing_treshold: 3\n", "policy.healing_treshold"),
    "wrong-type": ('policy:\n  healing_threshold: "x"\n', "policy.healing_threshold"),
    "wrong-nested-type": ("database:\n  max_batch: lots\n", "database.max_batch"),
    "not-a-mapping": ("- policy\n- database\n", "mapping"),
}


@pytest.mark.parametrize("name", list(CONFIGS))
def test_bad_config_file_exits_2_naming_file_and_field(tmp_path: Path, name: str) -> None:
    text, field = CONFIGS[name]
    config = tmp_path / "faultledger.yaml"
    config.write_text(text)
    done = run_cli("list", "--config", str(config), "--db", url(tmp_path / "faults.db"))
    assert_clean_error(done, str(config), field)
    assert done.returncode == 2


def test_missing_config_file_exits_2_naming_it(tmp_path: Path) -> None:
    config = tmp_path / "nowhere.yaml"
    done = run_cli("list", "--config", str(config), "--db", url(tmp_path / "faults.db"))
    assert_clean_error(done, str(config))
    assert done.returncode == 2


def test_invalid_yaml_with_brackets_exits_2_without_traceback(tmp_path: Path) -> None:
    """A flow-style key typo: the YAML error quotes the line, which contains ``[/...]``."""
    config = tmp_path / "faultledger.yaml"
    config.write_text("policy:\n  overrides: [/sensors/lidar]: {healing_enabled: true}\n")
    done = run_cli("list", "--config", str(config), "--db", url(tmp_path / "faults.db"))
    assert_clean_error(done, str(config), "not valid YAML")
    assert done.returncode == 2


def test_cli_option_value_with_brackets_is_rejected_without_traceback(tmp_path: Path) -> None:
    """Echoing the operator's bad value must not be interpreted as terminal markup."""
    path = tmp_path / "faults.db"
    length = make_ledger_file(path)
    done = run_cli("report", "ESTOP", "FAILED", "--at", "[/now]", "--db", url(path))
    assert_clean_error(done, "--at", "[/now]")
    assert done.returncode == 2
    assert log_length(path) == length
