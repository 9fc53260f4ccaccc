"""The PostgreSQL side of a rebuild's bulk load (store/dialects.py, ``bulk_load``): plain
indexes are dropped for the load and made again after it from their own definitions, in the
log's own schema (a fleet central keeps robot logs in schemas of one database). The schema
after a rebuild is the schema before; a load that fails leaves every index in place."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any

import psycopg
import pytest
from sqlalchemy import Connection, Table

from faultledger import FaultLedger, Policy
from faultledger.store import dialects
from faultledger.store.database import Database
from faultledger.store.schema import stat_facts, transitions
from tests import pg_server

START = datetime(2026, 11, 20, 8, 0, tzinfo=UTC)


def dsn(url: str) -> str:
    return url.replace("postgresql+psycopg", "postgresql")


def schema_of(url: str) -> list[tuple[str, str, str]]:
    """Every index of the database: schema, name, definition."""
    with psycopg.connect(dsn(url)) as conn:
        return [tuple(row) for row in conn.execute(
            "SELECT schemaname, indexname, indexdef FROM pg_indexes "
            "WHERE schemaname NOT IN ('pg_catalog', 'information_schema') ORDER BY 1, 2")]


def index_names_in(conn: Connection, table: str) -> set[str]:
    driver: Any = conn.connection.driver_connection
    with driver.cursor() as cursor:
        cursor.execute("SELECT indexname FROM pg_indexes WHERE tablename = %s", (table,))
        return {row[0] for row in cursor.fetchall()}


def fill(ledger: FaultLedger, n: int = 60) -> None:
    for i in range(n):
        result = ledger.report(f"BULK_{i % 5}", "FAILED" if i % 4 else "PASSED", 2, "",
                               "/arm", at=START + timedelta(seconds=i))
        assert result.accepted, result.message


def hourly(ledger: FaultLedger) -> list[dict[str, object]]:
    return [r.as_dict() for r in ledger.stats(
        "hour", "2026-11-20T00:00:00+00:00", "2026-11-21T00:00:00+00:00",
        as_of=START + timedelta(days=1))]


def test_a_rebuild_leaves_the_indexes_and_the_answers_as_they_were(
        postgres: pg_server.PostgresServer) -> None:
    url = postgres.database()
    with FaultLedger.open(url, policy=Policy(confirmation_threshold=-2),
                          background=False) as ledger:
        fill(ledger)
        before = schema_of(url)
        history = ledger.transitions("BULK_1")
        stats = hourly(ledger)
        plain = [name for _, name, ddl in before
                 if " ON public.stat_facts " in ddl and "UNIQUE" not in ddl]
        assert len(plain) >= 5, before  # what the load drops and makes again
        assert ledger.rebuild() == ledger.last_seq
        assert schema_of(url) == before
        assert history and ledger.transitions("BULK_1") == history
        assert hourly(ledger) == stats
        assert any(r["failed_reports"] and r["confirmations"] for r in stats)


def test_the_indexes_are_made_again_in_the_logs_own_schema(
        postgres: pg_server.PostgresServer) -> None:
    """A log in a schema (``?options=-csearch_path=NAME``) beside another in ``public``."""
    url = postgres.database()
    with psycopg.connect(dsn(url), autocommit=True) as conn:
        conn.execute("CREATE SCHEMA robot_7")
    with FaultLedger.open(url, background=False) as ledger:
        fill(ledger, 10)
    in_schema = f"{url}?options=-csearch_path%3Drobot_7"
    with FaultLedger.open(in_schema, background=False) as ledger:
        fill(ledger, 20)
        before = schema_of(url)
        assert {s for s, _, _ in before} == {"public", "robot_7"}
        assert ledger.rebuild() == ledger.last_seq
        assert schema_of(url) == before


@pytest.mark.parametrize(("appended", "kept"), [((), {"stat_facts_pkey"}),
                                                 ((stat_facts,), set())])
def test_a_load_that_fails_keeps_every_index(
        postgres: pg_server.PostgresServer, appended: tuple[Table, ...], kept: set[str]) -> None:
    """The primary key goes too only for a table the load only appends to."""
    url = postgres.database()
    with FaultLedger.open(url, background=False) as ledger:
        fill(ledger, 10)
    before = schema_of(url)
    db = Database(url)
    try:
        with (pytest.raises(RuntimeError, match="load failed"), db.writing() as conn,
              dialects.bulk_load(conn, (stat_facts, transitions), appended)):
            assert index_names_in(conn, "stat_facts") == kept  # dropped meanwhile
            raise RuntimeError("load failed")
    finally:
        db.dispose()
    assert schema_of(url) == before
