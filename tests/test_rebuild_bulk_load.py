"""A rebuild refills its tables with their plain indexes dropped and made again after
(store/dialects.py, ``bulk_load``): the schema after a rebuild is the schema before it, the
queries that use those indexes still answer the same, and a load that fails leaves every
index in place."""

from __future__ import annotations

import sqlite3
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import Connection

from faultledger import FaultLedger, Policy
from faultledger.store import dialects
from faultledger.store.database import Database
from faultledger.store.schema import stat_facts, transitions

START = datetime(2026, 11, 20, 8, 0, tzinfo=UTC)


def schema(path: Path) -> list[tuple[str, str, str]]:
    conn = sqlite3.connect(path)
    try:
        return [tuple(row) for row in conn.execute(
            "SELECT type, name, sql FROM sqlite_master WHERE sql IS NOT NULL ORDER BY name")]
    finally:
        conn.close()


def index_names(path: Path, table: str) -> set[str]:
    conn = sqlite3.connect(path)
    try:
        return {row[1] for row in conn.execute(f"PRAGMA index_list({table})")}
    finally:
        conn.close()


def fill(ledger: FaultLedger, n: int = 60) -> None:
    for i in range(n):
        result = ledger.report(f"BULK_{i % 5}", "FAILED" if i % 4 else "PASSED", 2, "",
                               "/arm", at=START + timedelta(seconds=i))
        assert result.accepted, result.message


def test_a_rebuild_leaves_the_schema_and_the_answers_as_they_were(tmp_path: Path) -> None:
    path = tmp_path / "log.db"
    with FaultLedger.open(f"sqlite:///{path}", policy=Policy(confirmation_threshold=-2),
                          background=False) as ledger:
        fill(ledger)
        before = schema(path)
        history = ledger.transitions("BULK_1")
        stats = [r.as_dict() for r in ledger.stats(
            "hour", "2026-11-20T00:00:00+00:00", "2026-11-21T00:00:00+00:00",
            as_of=START + timedelta(days=1))]
        assert len(index_names(path, "stat_facts")) >= 5  # what the load drops and remakes
        assert ledger.rebuild() == ledger.last_seq
        assert schema(path) == before
        assert ledger.transitions("BULK_1") == history
        assert history
        assert [r.as_dict() for r in ledger.stats(
            "hour", "2026-11-20T00:00:00+00:00", "2026-11-21T00:00:00+00:00",
            as_of=START + timedelta(days=1))] == stats
        assert any(r["failed_reports"] and r["confirmations"] for r in stats)


def test_a_load_that_fails_keeps_every_index(tmp_path: Path) -> None:
    path = tmp_path / "log.db"
    with FaultLedger.open(f"sqlite:///{path}", background=False) as ledger:
        fill(ledger, 10)
    expected = {name: index_names(path, name) for name in ("stat_facts", "transitions")}
    db = Database(f"sqlite:///{path}")
    try:
        with (pytest.raises(RuntimeError, match="load failed"), db.writing() as conn,
              dialects.bulk_load(conn, (stat_facts, transitions))):
            assert index_names_in(conn, "stat_facts") == set()  # dropped meanwhile
            raise RuntimeError("load failed")
    finally:
        db.dispose()
    assert {name: index_names(path, name) for name in expected} == expected


def index_names_in(conn: Connection, table: str) -> set[str]:
    driver: Any = conn.connection.driver_connection
    return {row[1] for row in driver.execute(f"PRAGMA index_list({table})")
            if row[3] == "c"}
