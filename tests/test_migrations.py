"""SPEC §3: the schema is created and changed by Alembic migrations only.

The migrations in ``src/faultledger/migrations/`` must produce exactly
``faultledger.store.schema.metadata``;
``FaultLedger.open`` and ``faultledger db upgrade`` bring a file to the head revision; read
commands never create or migrate anything.
"""

from __future__ import annotations

import contextlib
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import create_engine

from faultledger import FaultLedger
from faultledger.store.schema import metadata

MIGRATIONS = Path(__file__).resolve().parents[1] / "src" / "faultledger" / "migrations"
CLI = [sys.executable, "-m", "faultledger.cli.main"]


def head() -> str:
    heads = ScriptDirectory(str(MIGRATIONS)).get_heads()
    assert len(heads) == 1, f"migrations must have one head, found {heads}"
    return heads[0]


def url(path: Path) -> str:
    return f"sqlite:///{path}"


def revision_of(path: Path) -> str | None:
    engine = create_engine(url(path))
    try:
        with engine.connect() as conn:
            return MigrationContext.configure(conn).get_current_revision()
    finally:
        engine.dispose()


def schema_differences(path: Path) -> list[object]:
    engine = create_engine(url(path))
    try:
        with engine.connect() as conn:
            context = MigrationContext.configure(conn, opts={"compare_type": True})
            return list(compare_metadata(context, metadata))
    finally:
        engine.dispose()


def tables_in(path: Path) -> set[str]:
    with contextlib.closing(sqlite3.connect(path)) as conn:
        return {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=60)


def alembic_on(path: Path, action: str, target: str) -> None:
    """Run an Alembic command on the file through the package's migrations/env.py."""
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    engine = create_engine(url(path))
    try:
        with engine.connect() as conn:
            config.attributes["connection"] = conn
            getattr(command, action)(config, target)
            conn.commit()
    finally:
        engine.dispose()


def test_open_applies_head_revision_to_a_fresh_file(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    FaultLedger.open(url(path)).close()
    assert revision_of(path) == head()


def test_schema_from_migrations_equals_metadata(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    FaultLedger.open(url(path)).close()
    assert schema_differences(path) == []


def test_schema_from_plain_alembic_upgrade_equals_metadata(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    alembic_on(path, "upgrade", "head")
    assert revision_of(path) == head()
    assert schema_differences(path) == []


def test_downgrade_to_base_then_upgrade_gives_the_same_schema(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    alembic_on(path, "upgrade", "head")
    alembic_on(path, "downgrade", "base")
    assert tables_in(path) <= {"alembic_version"}
    alembic_on(path, "upgrade", "head")
    assert schema_differences(path) == []


def test_event_seq_is_the_sqlite_rowid(tmp_path: Path) -> None:
    """``seq INTEGER PRIMARY KEY``: appends and seq lookups use the table's own b-tree key."""
    path = tmp_path / "faults.db"
    FaultLedger.open(url(path)).close()
    with contextlib.closing(sqlite3.connect(path)) as conn:
        columns = {r[1]: (r[2], r[5]) for r in conn.execute("PRAGMA table_info(events)")}
    assert columns["seq"] == ("INTEGER", 1)


def test_reopening_a_current_database_leaves_its_revision(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    with FaultLedger.open(url(path)) as ledger:
        assert ledger.report("MOTOR_OVERHEAT", "FAILED", 2, "", "/motor").accepted
    with FaultLedger.open(url(path)) as ledger:
        assert [r.kind for r in ledger.history()] == [
            "ledger_identified", "policy_changed", "fault_reported"]
    assert revision_of(path) == head()


def test_cli_db_upgrade_creates_a_database_at_head(tmp_path: Path) -> None:
    path = tmp_path / "new" / "faults.db"
    done = run_cli("db", "upgrade", "--db", url(path))
    assert done.returncode == 0, done.stderr
    assert head() in done.stdout
    assert "(empty)" in done.stdout
    assert revision_of(path) == head()
    assert schema_differences(path) == []


def test_cli_db_upgrade_twice_is_a_no_op(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    FaultLedger.open(url(path)).close()
    done = run_cli("db", "upgrade", "--db", url(path))
    assert done.returncode == 0, done.stderr
    assert f"{head()} -> {head()}" in done.stdout
    assert revision_of(path) == head()


def test_cli_db_current_reports_head_and_up_to_date(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    FaultLedger.open(url(path)).close()
    done = run_cli("db", "current", "--db", url(path))
    assert done.returncode == 0, done.stderr
    assert head() in done.stdout
    assert "up to date" in done.stdout


def sqlite_without_tables(path: Path) -> None:
    """An SQLite file with its header and no table (a 0-byte file is refused outright:
    tests/test_bad_database.py)."""
    with contextlib.closing(sqlite3.connect(path)) as conn:
        conn.execute("PRAGMA journal_mode = WAL")
    assert path.stat().st_size > 0


def test_cli_db_current_on_an_empty_sqlite_file_says_upgrade_is_needed(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    sqlite_without_tables(path)
    done = run_cli("db", "current", "--db", url(path))
    assert done.returncode == 0, done.stderr
    assert "(empty)" in done.stdout
    assert "db upgrade" in done.stdout
    assert tables_in(path) == set()


@pytest.mark.parametrize("command_", [["db", "current"], ["list"], ["verify"]],
                         ids=["db-current", "list", "verify"])
def test_cli_read_command_on_a_missing_file_does_not_create_it(tmp_path: Path,
                                                               command_: list[str]) -> None:
    path = tmp_path / "missing.db"
    done = run_cli(*command_, "--db", url(path))
    assert done.returncode != 0
    assert "Traceback" not in done.stderr
    assert "does not exist" in done.stderr
    assert not path.exists()


def test_cli_read_command_on_an_unmigrated_file_asks_for_upgrade(tmp_path: Path) -> None:
    path = tmp_path / "faults.db"
    sqlite_without_tables(path)
    done = run_cli("list", "--db", url(path))
    assert done.returncode != 0
    assert "Traceback" not in done.stderr
    assert "faultledger db upgrade" in done.stderr
    assert tables_in(path) == set()
