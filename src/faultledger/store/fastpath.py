"""Hot-path execution: SQLAlchemy-compiled statements run straight on the DBAPI cursor.

Building and executing a SQLAlchemy Core statement costs ~50 µs of Python per call, more than
SQLite needs to insert a row. The ingest path runs a handful of statements per group commit,
so it compiles each statement once per dialect (the SQL text still comes from the table
definitions in ``schema``) and hands rows to ``cursor.executemany`` inside the connection's
current transaction. Only plain column types (int, str, bool) go through this path, which
need no SQLAlchemy bind processing.
"""

from __future__ import annotations

from collections.abc import Generator, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from operator import itemgetter
from typing import Any

from sqlalchemy import Connection, Table
from sqlalchemy.engine import Dialect
from sqlalchemy.sql import ClauseElement
from sqlalchemy.sql.dml import Insert

from faultledger.store.dialects import rules_for


@dataclass(frozen=True, slots=True)
class Prepared:
    sql: str
    order: tuple[str, ...] | None
    """Parameter names in positional order, or None for a named paramstyle."""
    defaults: Mapping[str, Any]
    """Values bound in the statement itself (e.g. a LIMIT)."""

    def params(self, row: Mapping[str, Any]) -> Any:
        if self.defaults:
            row = {**self.defaults, **row}
        if self.order is None:
            return row
        return tuple(row[name] for name in self.order)

    def params_many(self, rows: Sequence[Mapping[str, Any]]) -> list[Any]:
        if self.defaults or self.order is None:
            return [self.params(row) for row in rows]
        if len(self.order) == 1:
            only = self.order[0]
            return [(row[only],) for row in rows]
        pick = itemgetter(*self.order)
        return [pick(row) for row in rows]


@lru_cache(maxsize=64)
def prepare(statement: ClauseElement, dialect: Dialect) -> Prepared:
    compiled: Any = statement.compile(dialect=dialect)  # a SQLCompiler for these statements
    order = tuple(compiled.positiontup or ()) if compiled.positional else None
    defaults = {k: v for k, v in compiled.params.items() if v is not None}
    return Prepared(str(compiled), order, defaults)


def _cursor(conn: Connection) -> Any:
    return conn.connection.driver_connection.cursor()  # type: ignore[union-attr]


def execute_many(conn: Connection, statement: ClauseElement,
                 rows: Sequence[Mapping[str, Any]]) -> None:
    if not rows:
        return
    if _plain_insert(statement) and conn.dialect.name != "sqlite":
        # PostgreSQL: COPY (store/dialects.py), several times faster than executemany.
        table: Any = statement.table  # type: ignore[attr-defined]
        rules_for(conn.dialect.name).insert_rows(conn, table, *_columns_and_tuples(rows))
        return
    prepared = prepare(statement, conn.dialect)
    if (len(rows) >= BULK_UPSERT_ROWS and conn.dialect.name != "sqlite"
            and isinstance(statement, Insert) and " ON CONFLICT " in prepared.sql):
        target: Any = statement.table
        rules_for(conn.dialect.name).upsert_rows(conn, target, *_columns_and_tuples(rows),
                                                 prepared.sql)
        return
    params = prepared.params_many(rows)
    cursor = _cursor(conn)
    try:
        if (conn.dialect.name == "sqlite" and len(rows) > 1 and prepared.order is not None
                and isinstance(statement, Insert)):
            _insert_together(cursor, prepared.sql, params)
        else:
            cursor.executemany(prepared.sql, params)
    finally:
        cursor.close()


def insert_tuples(conn: Connection, table: Table, columns: tuple[str, ...],
                  rows: Sequence[Sequence[Any]]) -> None:
    """Rows of plain values (int, str, None) into ``table`` in the caller's transaction: on
    SQLite one statement per row or per 500 rows (``_insert_together``), elsewhere the
    dialect's bulk path (PostgreSQL: COPY). The ingest path's append: no compiled statement
    to look up and no dict per row."""
    if not rows:
        return
    if conn.dialect.name != "sqlite":
        rules_for(conn.dialect.name).insert_rows(conn, table, columns, rows)
        return
    sql = _insert_sql(table.name, columns)
    driver: Any = conn.connection.driver_connection
    if len(rows) == 1:
        driver.execute(sql, rows[0])
        return
    cursor = driver.cursor()
    try:
        _insert_together(cursor, sql, rows)
    finally:
        cursor.close()


@lru_cache(maxsize=64)
def _insert_sql(table: str, columns: tuple[str, ...]) -> str:
    return (f"INSERT INTO {table} ({', '.join(columns)}) "
            f"VALUES ({', '.join('?' for _ in columns)})")


MAX_ROWS_PER_STATEMENT = 500
"""Rows one multi-row INSERT writes on SQLite (columns × rows stays far below SQLite's
32,766 variables)."""


def _insert_together(cursor: Any, sql: str, params: Sequence[Any]) -> None:
    """SQLite: the rows of an INSERT (or upsert) as multi-row statements. ``executemany``
    steps once per row and Python's sqlite3 lets go of the GIL at every step; while another
    thread computes (a long statistics query), getting it back takes up to the switch
    interval each time, so a save of a few hundred rows took seconds (tests/ros/
    test_read_pool.py). One statement per 500 rows takes it back once."""
    for start in range(0, len(params), MAX_ROWS_PER_STATEMENT):
        chunk = params[start:start + MAX_ROWS_PER_STATEMENT]
        values = [value for row in chunk for value in row]
        cursor.execute(_multi_row(sql, len(chunk)), values)


@lru_cache(maxsize=512)
def _multi_row(sql: str, rows: int) -> str:
    """``INSERT ... VALUES (?, ?) [ON CONFLICT ...]`` with the VALUES group repeated."""
    head, found, rest = sql.partition(" VALUES (")
    group, closed, tail = rest.partition(")")
    if not found or not closed or group.replace("?", "").replace(",", "").strip():
        raise ValueError(f"not a plain positional INSERT: {sql[:80]}")
    one = f"({group})"
    return f"{head} VALUES {','.join([one] * rows)}{tail}"


def _columns_and_tuples(rows: Sequence[Mapping[str, Any]]
                        ) -> tuple[tuple[str, ...], list[tuple[Any, ...]]]:
    """Rows of one shape as their column names and value tuples (what COPY writes)."""
    columns = tuple(rows[0])
    if len(columns) == 1:
        return columns, [(row[columns[0]],) for row in rows]
    pick = itemgetter(*columns)
    return columns, [pick(row) for row in rows]


BULK_UPSERT_ROWS = 64
"""From this many rows an upsert on PostgreSQL goes through COPY into a temporary table."""


def _plain_insert(statement: ClauseElement) -> bool:
    """An INSERT of given rows with no ON CONFLICT clause (those can be COPYed)."""
    return (isinstance(statement, Insert) and statement.table is not None
            and getattr(statement, "_post_values_clause", None) is None
            and not statement._multi_values)


def execute(conn: Connection, statement: ClauseElement,
            params: Mapping[str, Any] | None = None) -> None:
    """One statement that returns no rows (an ``INSERT ... SELECT``), compiled once."""
    prepared = prepare(statement, conn.dialect)
    cursor = _cursor(conn)
    try:
        cursor.execute(prepared.sql, prepared.params(params or {}))
    finally:
        cursor.close()


def stream(conn: Connection, statement: ClauseElement, params: Mapping[str, Any],
           size: int) -> Generator[tuple[Any, ...], None, None]:
    """Every row of one statement, ``size`` at a time, for a caller that reads to the end.

    PostgreSQL sends the rows as it makes them while the caller works on those before
    (psycopg's ``stream``): pages of ``LIMIT`` rows each wait a round trip and the server's
    work, and a replay of a million records took 6.0 s that way against 5.0 s streamed
    (docs/performance.md, "Thirteenth round"). The connection runs nothing else until the
    last row. A caller that stops early (a record it cannot apply) gets the rest read and
    dropped: closing the stream would cancel the statement, and with it the transaction."""
    prepared = prepare(statement, conn.dialect)
    cursor = _cursor(conn)
    try:
        if conn.dialect.name == "postgresql":
            rows = cursor.stream(prepared.sql, prepared.params(params), size=size)
            try:
                for row in rows:  # noqa: UP028 (``yield from`` would close ``rows`` with us)
                    yield row
            finally:
                for _ in rows:
                    pass
        else:
            cursor.execute(prepared.sql, prepared.params(params))
            while chunk := cursor.fetchmany(size):
                yield from chunk
    finally:
        cursor.close()


def fetch_one(conn: Connection, statement: ClauseElement,
              params: Mapping[str, Any] | None = None) -> tuple[Any, ...] | None:
    prepared = prepare(statement, conn.dialect)
    cursor = _cursor(conn)
    try:
        cursor.execute(prepared.sql, prepared.params(params or {}))
        row = cursor.fetchone()
    finally:
        cursor.close()
    return None if row is None else tuple(row)


def fetch_all(conn: Connection, statement: ClauseElement,
              params: Mapping[str, Any] | None = None) -> list[tuple[Any, ...]]:
    prepared = prepare(statement, conn.dialect)
    cursor = _cursor(conn)
    try:
        cursor.execute(prepared.sql, prepared.params(params or {}))
        rows: list[tuple[Any, ...]] = cursor.fetchall()
    finally:
        cursor.close()
    return rows


def fetch_all_rendered(conn: Connection, statement: ClauseElement) -> list[tuple[Any, ...]]:
    """Run a read whose parameters are plain ints and strings with every value rendered into
    the SQL by SQLAlchemy's own literal quoting, straight on the DBAPI cursor.

    For reads of tens of thousands of rows (statistics facts), where SQLAlchemy's per-row
    result processing costs more than SQLite's work; ``IN`` lists need no expansion step.
    """
    sql = str(statement.compile(dialect=conn.dialect, compile_kwargs={"literal_binds": True}))
    return _fetch_sql(conn, sql)


EACH_SCHEMA = "faultledger_each_log"
"""Stands for a log's schema in a statement rendered once for many schemas (a plain
lower-case identifier: replaced as text, it can never be a quoted part of the SQL)."""


def fetch_all_in_schemas(conn: Connection, statement: ClauseElement, schemas: Sequence[str],
                         shared: Sequence[str] = ()) -> list[list[tuple[Any, ...]]]:
    """The rows of one read in each of ``schemas`` (tables of the same shape, a fleet
    central's robot logs), as one ``UNION ALL`` statement: one round trip and one plan for
    every log, instead of one each. Rendered like ``fetch_all_rendered``; each schema name
    must be a plain identifier (store/fleet_log.py makes them). ``shared``: common table
    expressions (``name AS (...)``) the statement reads, written once for all logs."""
    if not schemas:
        return []
    compiled = statement.compile(
        dialect=conn.dialect, schema_translate_map={None: EACH_SCHEMA},
        render_schema_translate=True, compile_kwargs={"literal_binds": True})
    sql = str(compiled)
    for schema in schemas:
        if not schema.isidentifier() or schema != schema.lower():
            raise ValueError(f"not a plain schema name: {schema!r}")
    union = ("WITH " + ", ".join(shared) + " " if shared else "") + " UNION ALL ".join(
        f"SELECT {n} AS faultledger_log, q.* FROM ({sql.replace(EACH_SCHEMA, schema)}) AS q"
        for n, schema in enumerate(schemas))
    found: list[list[tuple[Any, ...]]] = [[] for _ in schemas]
    for row in _fetch_sql(conn, union):
        found[row[0]].append(tuple(row[1:]))
    return found


def _fetch_sql(conn: Connection, sql: str) -> list[tuple[Any, ...]]:
    cursor = _cursor(conn)
    try:
        cursor.execute(sql)
        rows: list[tuple[Any, ...]] = cursor.fetchall()
    finally:
        cursor.close()
    return rows
