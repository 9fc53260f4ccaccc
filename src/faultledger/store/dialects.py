"""What differs between SQLite and PostgreSQL, one small strategy per dialect.

Every writer of one log serialises on one lock held for its whole transaction, re-reads the
head of the log under that lock and appends after it; a reader sees one consistent snapshot.
How each database gives that:

=====================  ==================================  =======================================
                       SQLite                              PostgreSQL
=====================  ==================================  =======================================
write lock             ``BEGIN IMMEDIATE`` (file lock,     ``pg_advisory_xact_lock(WRITE_LOCK)``
                       busy_timeout 5 s)                   (lock_timeout 5 s), READ COMMITTED
read snapshot          ``BEGIN`` (WAL snapshot)            REPEATABLE READ
another writer         ``PRAGMA data_version`` changed     always re-read the head (one index seek)
committed
schema upgrade         the write lock                      ``pg_advisory_lock(MIGRATE_LOCK)``
same seq appended      IntegrityError: write conflict      UniqueViolation: write conflict
=====================  ==================================  =======================================

A write conflict is never "internal": the writer catches up with the other process's
records and retries (service/writer.py).
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
from collections.abc import Iterator, Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any

from sqlalchemy import Connection, Engine, MetaData, Table, event, exc
from sqlalchemy.dialects import postgresql, sqlite

from faultledger.errors import (
    DatabaseFullError,
    DatabaseLockedError,
    DatabaseReadOnlyError,
    NotADatabaseError,
    StoreError,
    WriteConflictError,
)

BUSY_TIMEOUT_MS = 5_000
"""How long a writer waits for another one's lock before "locked" (both dialects)."""
JOURNAL_SIZE_LIMIT = 4 * 1024 * 1024
"""Bytes a WAL file keeps after a checkpoint (SQLite's default auto-checkpoint size): the WAL
never stays larger than that, so a disk that was full gets its space back."""
WAL_WORKING_SIZE = JOURNAL_SIZE_LIMIT
"""Bytes of zeros a serving writer gives a new WAL file (``presize_wal``): the WAL's size
between checkpoints (1,000 frames of 4,120 bytes fit)."""
WRITE_LOCK = 0x66_6C_65_64_67_72_77  # "fledgrw": one key per database, so per log
MIGRATE_LOCK = 0x66_6C_65_64_67_6D_67  # "fledgmg"

_LOCKED = f"is locked by another process (waited {BUSY_TIMEOUT_MS / 1000:.0f} s)"


class DialectRules:
    """The defaults: a database that needs nothing special (never used as such)."""

    name = "generic"

    def configure(self, engine: Engine) -> None:
        """Hook the engine's connect/begin events."""

    def others_committed(self, conn: Connection, last: object) -> tuple[bool, object]:
        """(whether another connection committed since ``last``, the new token)."""
        return True, None

    @contextlib.contextmanager
    def migration_lock(self, conn: Connection) -> Iterator[None]:
        """Held while a process checks and upgrades the schema: one process migrates."""
        yield

    @contextlib.contextmanager
    def unflushed(self, conn: Connection) -> Iterator[Connection]:
        """The transaction begun inside commits without waiting for the disk."""
        yield conn

    def driver_errors(self) -> tuple[type[BaseException], ...]:
        return ()

    def upsert_rows(self, conn: Connection, table: Table, columns: Sequence[str],
                    rows: Sequence[Sequence[Any]], upsert_sql: str) -> None:
        """Many rows through ``upsert_sql`` (INSERT … VALUES … ON CONFLICT …): executemany."""
        driver: Any = conn.connection.driver_connection
        cursor = driver.cursor()
        try:
            cursor.executemany(upsert_sql, [dict(zip(columns, row, strict=True))
                                            for row in rows])
        finally:
            cursor.close()

    def classify(self, where: str, text: str, error: BaseException) -> StoreError | None:
        return None

    @contextlib.contextmanager
    def bulk_load(self, conn: Connection, tables: Sequence[Table],
                  appended: Sequence[Table] = ()) -> Iterator[None]:
        """Around the refill of emptied ``tables`` (a rebuild): whatever makes a bulk load
        cheaper without changing what readers see once it commits (here: nothing).
        ``appended``: those of ``tables`` the load only INSERTs into (no upsert, update or
        lookup by key), whose primary key may go too."""
        yield

    def insert_rows(self, conn: Connection, table: Table, columns: Sequence[str],
                    rows: Sequence[Sequence[Any]]) -> None:
        """Many rows of plain values (int, str, None) into ``table``, in the caller's
        transaction, the fastest way the database offers (executemany here)."""
        if not rows:
            return
        marks = ", ".join("?" if self.name == "sqlite" else "%s" for _ in columns)
        driver: Any = conn.connection.driver_connection
        cursor = driver.cursor()
        try:
            cursor.executemany(f"INSERT INTO {table.name} ({', '.join(columns)}) "
                               f"VALUES ({marks})", rows)
        finally:
            cursor.close()


def presize_wal(database: Path) -> None:
    """Fill the WAL file with zeros from its end to its working size, once, with the write
    lock held (no other connection appends frames meanwhile; no byte before the end is
    touched).

    A commit that makes the WAL longer changes the file's size, and its fdatasync then
    commits the file system's journal too: after SQLite made a new WAL (at every start, as
    it deletes the WAL when its last connection closes) the first ~900 commits of one reporter
    took 200-260 µs instead of 110 (docs/performance.md, "Twelfth round"). Zeros past the
    last frame are no frames to SQLite (a frame counts only with the header's salt and the
    running checksum), as PostgreSQL fills each WAL segment with zeros before using it.
    Best effort: on an error (a full disk) the file is cut back to the size it had. SQLite
    holds no lock on the -wal file (its locks are on the database and -shm files), so
    opening and closing it here releases none of them."""
    try:
        fd = os.open(database.with_name(database.name + "-wal"), os.O_WRONLY)
    except OSError:
        return
    try:
        size = os.fstat(fd).st_size
        if size >= WAL_WORKING_SIZE:
            return
        zeros = bytes(WAL_WORKING_SIZE - size)
        try:
            if os.pwrite(fd, zeros, size) != len(zeros):  # short: the disk is full
                raise OSError("short write")
            os.fdatasync(fd)
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, size)
    finally:
        os.close(fd)


class SQLiteRules(DialectRules):
    name = "sqlite"

    def configure(self, engine: Engine) -> None:
        event.listen(engine, "connect", _sqlite_connect)
        event.listen(engine, "begin", _sqlite_begin)

    def others_committed(self, conn: Connection, last: object) -> tuple[bool, object]:
        driver: Any = conn.connection.driver_connection
        version = int(driver.execute("PRAGMA data_version").fetchone()[0])
        return version != last, version

    def driver_errors(self) -> tuple[type[BaseException], ...]:
        return (sqlite3.Error,)

    @contextlib.contextmanager
    def unflushed(self, conn: Connection) -> Iterator[Connection]:
        """synchronous=NORMAL on this connection (WAL: the commit is not fsynced; the next
        FULL commit of any connection fsyncs it too), and FULL again after, whatever
        happened: the pool's connections stay durable for every other writer."""
        driver: Any = conn.connection.driver_connection
        driver.execute("PRAGMA synchronous = NORMAL")
        try:
            yield conn
        finally:
            driver.execute("PRAGMA synchronous = FULL")

    @contextlib.contextmanager
    def bulk_load(self, conn: Connection, tables: Sequence[Table],
                  appended: Sequence[Table] = ()) -> Iterator[None]:
        """The tables' plain secondary indexes are dropped before the load and made again
        from their own stored DDL after it, in the same transaction: sorting a million
        keys once is three times cheaper than inserting them one by one into five B-trees
        (docs/performance.md, "Rebuild"). Unique indexes stay (upserts need them). WAL
        readers keep their snapshot meanwhile; a failed load rolls the drops back with it.
        Primary keys stay (``appended`` changes nothing: SQLite's keys are the rowid)."""
        driver: Any = conn.connection.driver_connection
        made: list[str] = []
        for table in tables:
            for _, name, unique, origin, *_ in driver.execute(
                    f'PRAGMA index_list("{table.name}")').fetchall():
                if origin != "c" or unique:
                    continue
                (ddl,) = driver.execute("SELECT sql FROM sqlite_master WHERE type = 'index' "
                                        "AND name = ?", (name,)).fetchone()
                driver.execute(f'DROP INDEX "{name}"')
                made.append(ddl)
        yield
        for ddl in made:
            driver.execute(ddl)

    def classify(self, where: str, text: str, error: BaseException) -> StoreError | None:
        if isinstance(error, sqlite3.IntegrityError | exc.IntegrityError):
            return WriteConflictError(f"{where}: concurrent append ({text})")
        for needle, kind, message in _SQLITE_MESSAGES:
            if needle in text.lower():
                return kind(f"{where} {message}")
        return None


_SQLITE_MESSAGES: tuple[tuple[str, type[StoreError], str], ...] = (
    ("file is not a database", NotADatabaseError, "is not a faultledger database (not SQLite)"),
    ("readonly database", DatabaseReadOnlyError, "is read-only; nothing was written"),
    ("read-only", DatabaseReadOnlyError, "is read-only; nothing was written"),
    ("database is locked", DatabaseLockedError, _LOCKED),
    ("disk is full", DatabaseFullError, "cannot grow: the disk or database is full"),
    ("unable to open database", StoreError, "cannot be opened (missing directory or no access)"),
    ("disk i/o error", StoreError, "hit an I/O error on disk"),
)


def _sqlite_connect(dbapi_connection: Any, _record: Any) -> None:
    dbapi_connection.isolation_level = None  # we issue BEGIN ourselves (see _sqlite_begin)
    cursor = dbapi_connection.cursor()
    cursor.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
    with contextlib.suppress(sqlite3.OperationalError):  # a read-only file keeps its mode
        cursor.execute("PRAGMA journal_mode = WAL")
    cursor.execute("PRAGMA synchronous = FULL")
    cursor.execute(f"PRAGMA journal_size_limit = {JOURNAL_SIZE_LIMIT}")
    # Statistics join a VALUES list of periods to time ranges; with many periods SQLite's
    # planner would build a throw-away automatic index instead of using ours (50× slower).
    cursor.execute("PRAGMA automatic_index = OFF")
    # Temporary storage in memory: a group commit's multi-row INSERT needs a statement
    # journal, which SQLite spills to a new file in /var/tmp past 64 KiB (created, written,
    # unlinked: once per ~25 reports of 8 callers, more as the log grows), and a robot's
    # root file system may be read-only (docs/performance.md, "Eleventh round").
    cursor.execute("PRAGMA temp_store = MEMORY")
    cursor.close()


def _sqlite_begin(conn: Connection) -> None:
    write = conn.get_execution_options().get("faultledger_write", False)
    driver: Any = conn.connection.driver_connection  # cheaper than exec_driver_sql per batch
    driver.execute("BEGIN IMMEDIATE" if write else "BEGIN")


class PostgreSQLRules(DialectRules):
    """PostgreSQL through psycopg 3. Writers stay READ COMMITTED: a REPEATABLE READ snapshot
    would be taken before the lock is granted and miss the previous writer's records."""

    name = "postgresql"

    def configure(self, engine: Engine) -> None:
        event.listen(engine, "begin", _postgresql_begin)

    @contextlib.contextmanager
    def migration_lock(self, conn: Connection) -> Iterator[None]:
        conn.exec_driver_sql(f"SELECT pg_advisory_lock({MIGRATE_LOCK})")
        conn.commit()
        try:
            yield
        finally:
            conn.rollback()
            conn.exec_driver_sql(f"SELECT pg_advisory_unlock({MIGRATE_LOCK})")
            conn.commit()

    def insert_rows(self, conn: Connection, table: Table, columns: Sequence[str],
                    rows: Sequence[Sequence[Any]]) -> None:
        _copy_rows(conn, table, columns, rows)

    @contextlib.contextmanager
    def bulk_load(self, conn: Connection, tables: Sequence[Table],
                  appended: Sequence[Table] = ()) -> Iterator[None]:
        """As on SQLite, the tables' plain indexes are dropped before the load and made again
        from their own definitions after it, in the same transaction; so is the primary key
        of the ``appended`` tables. The rows the rebuild deleted are still in the table
        until a vacuum, and each new row's key was checked against the dead one of the same
        seq: a million statistics facts took 3.6 s to COPY, 1.8 s without the indexes
        (docs/performance.md, "Seventh round").

        The price: DROP INDEX locks the table exclusively until the commit, so readers of
        these tables wait for the load (about 5 s per million records here) instead of
        reading the snapshot before it. Writers wait for the whole rebuild anyway."""
        from psycopg import sql

        driver: Any = conn.connection.driver_connection
        made: list[sql.Composable] = []
        with driver.cursor() as cursor:
            for table in tables:
                cursor.execute(_PLAIN_INDEXES, (table.name,))
                for schema, name, ddl in cursor.fetchall():
                    cursor.execute(sql.SQL("DROP INDEX {}").format(sql.Identifier(schema, name)))
                    made.append(sql.SQL(ddl))
            for table in appended:
                cursor.execute(_PRIMARY_KEY, (table.name,))
                for schema, relation, name, definition in cursor.fetchall():
                    target = sql.Identifier(schema, relation)
                    cursor.execute(sql.SQL("ALTER TABLE {} DROP CONSTRAINT {}").format(
                        target, sql.Identifier(name)))
                    made.append(sql.SQL("ALTER TABLE {} ADD CONSTRAINT {} {}").format(
                        target, sql.Identifier(name), sql.SQL(definition)))
        yield
        with driver.cursor() as cursor:
            for statement in made:
                cursor.execute(statement)

    @contextlib.contextmanager
    def unflushed(self, conn: Connection) -> Iterator[Connection]:
        """synchronous_commit off for the transaction begun inside (SET LOCAL at its
        begin: the setting ends with it)."""
        yield conn.execution_options(faultledger_unflushed=True)

    def upsert_rows(self, conn: Connection, table: Table, columns: Sequence[str],
                    rows: Sequence[Sequence[Any]], upsert_sql: str) -> None:
        """COPY into a temporary table, then one INSERT … SELECT … ON CONFLICT (the same
        conflict clause): a batch's rows in two statements instead of one each (the rows of
        one batch have distinct keys, as ON CONFLICT … DO UPDATE requires)."""
        staging = f"faultledger_staging_{table.name}"
        driver: Any = conn.connection.driver_connection
        with driver.cursor() as cursor:
            cursor.execute(f"CREATE TEMP TABLE IF NOT EXISTS {staging} (LIKE {table.name}) "
                           "ON COMMIT DELETE ROWS")
        _copy_rows(conn, Table(staging, MetaData()), columns, rows)
        start = upsert_sql.index(" VALUES (")
        end = upsert_sql.index(") ON CONFLICT ", start)
        listed = ", ".join(columns)
        sql = (f"{upsert_sql[:upsert_sql.index('(', 0, start)]}({listed}) SELECT {listed} "
               f"FROM {staging}{upsert_sql[end + 1:]}")
        with driver.cursor() as cursor:
            cursor.execute(sql)

    def driver_errors(self) -> tuple[type[BaseException], ...]:
        try:
            import psycopg
        except ImportError:  # pragma: no cover - the URL check names the missing extra
            return ()
        return (psycopg.Error,)

    def classify(self, where: str, text: str, error: BaseException) -> StoreError | None:
        state = getattr(getattr(error, "orig", None) or error, "sqlstate", None) or ""
        first_line = text.strip().splitlines()[0] if text.strip() else text
        if state == "23505":  # unique_violation: another writer appended this seq first
            return WriteConflictError(f"{where}: concurrent append ({first_line})")
        if state in ("55P03", "40P01"):  # lock_not_available, deadlock_detected
            return DatabaseLockedError(f"{where} {_LOCKED}")
        if state in ("53100",):  # disk_full
            return DatabaseFullError(f"{where} cannot grow: the disk or database is full")
        if state == "25006":  # read_only_sql_transaction (a standby, or read-only default)
            return DatabaseReadOnlyError(f"{where} is read-only; nothing was written")
        if state == "3D000":
            return StoreError(f"{where} does not exist (create it: createdb NAME)")
        if state.startswith("28"):
            return StoreError(f"{where} refused the login ({first_line})")
        if "connection" in text.lower() and ("refused" in text.lower()
                                             or "failed" in text.lower()):
            return StoreError(f"{where} cannot be reached ({first_line})")
        return None


_PLAIN_INDEXES = (
    "SELECT n.nspname, i.relname, pg_get_indexdef(i.oid) FROM pg_index x "
    "JOIN pg_class i ON i.oid = x.indexrelid JOIN pg_namespace n ON n.oid = i.relnamespace "
    "WHERE x.indrelid = to_regclass(%s) AND NOT x.indisunique AND NOT x.indisprimary "
    "AND NOT EXISTS (SELECT 1 FROM pg_constraint c WHERE c.conindid = i.oid) "
    "ORDER BY i.relname")
"""The table's (found on the transaction's search_path) indexes that no constraint or
upsert needs: schema, name and the statement that makes it again."""
_PRIMARY_KEY = (
    "SELECT n.nspname, t.relname, c.conname, pg_get_constraintdef(c.oid) FROM pg_constraint c "
    "JOIN pg_class t ON t.oid = c.conrelid JOIN pg_namespace n ON n.oid = t.relnamespace "
    "WHERE c.conrelid = to_regclass(%s) AND c.contype = 'p' "
    "AND NOT EXISTS (SELECT 1 FROM pg_constraint f WHERE f.confrelid = c.conrelid)")
"""The table's primary key, unless a foreign key refers to the table: schema, table,
constraint name and definition."""


def _copy_rows(conn: Connection, table: Table, columns: Sequence[str],
               rows: Sequence[Sequence[Any]]) -> None:
    """PostgreSQL's COPY: about 8× faster than executemany for a fleet batch (bench/fleet.py)."""
    if not rows:
        return
    driver: Any = conn.connection.driver_connection
    with driver.cursor() as cursor, cursor.copy(
            f"COPY {table.name} ({', '.join(columns)}) FROM STDIN") as copy:
        for row in rows:
            copy.write_row(row)


def _postgresql_begin(conn: Connection) -> None:
    """The transaction's settings and lock, sent as one query (one round trip)."""
    driver: Any = conn.connection.driver_connection
    options = conn.get_execution_options()
    schema = options.get("faultledger_schema")
    write = options.get("faultledger_write", False)
    statements = [] if write else ["SET TRANSACTION ISOLATION LEVEL REPEATABLE READ"]
    if schema is not None:  # a log in a schema of this database (a central's robot log)
        statements.append(f'SET LOCAL search_path TO "{schema}"')
    if options.get("faultledger_unflushed", False):
        statements.append("SET LOCAL synchronous_commit = off")
    if write:
        key = int(options.get("faultledger_lock_key", WRITE_LOCK))
        statements.append(f"SET LOCAL lock_timeout = {BUSY_TIMEOUT_MS}")
        statements.append(f"SELECT pg_advisory_xact_lock({key})")
    driver.execute("; ".join(statements))


_RULES: dict[str, DialectRules] = {"sqlite": SQLiteRules(), "postgresql": PostgreSQLRules()}


def rules_for(dialect_name: str) -> DialectRules:
    return _RULES.get(dialect_name, DialectRules())


def bulk_load(conn: Connection, tables: Sequence[Table], appended: Sequence[Table] = ()
              ) -> contextlib.AbstractContextManager[None]:
    """``DialectRules.bulk_load`` of the connection's database."""
    return rules_for(conn.dialect.name).bulk_load(conn, tables, appended)


@lru_cache(maxsize=16)
def upsert(table: Table, dialect_name: str) -> Any:
    """INSERT ... ON CONFLICT (primary key) DO UPDATE SET every other column (executemany).

    Built once per table and dialect: constructing SQLAlchemy statements costs more than
    executing them on the ingest path.
    """
    module: Any = postgresql if dialect_name == "postgresql" else sqlite
    statement = module.insert(table)
    keys = [c.name for c in table.primary_key.columns]
    return statement.on_conflict_do_update(
        index_elements=keys,
        set_={c.name: statement.excluded[c.name] for c in table.columns if c.name not in keys},
    )


@lru_cache(maxsize=16)
def upsert_add(table: Table, dialect_name: str) -> Any:
    """INSERT ... ON CONFLICT (primary key) DO UPDATE SET column = column + new value."""
    module: Any = postgresql if dialect_name == "postgresql" else sqlite
    statement = module.insert(table)
    keys = [c.name for c in table.primary_key.columns]
    return statement.on_conflict_do_update(
        index_elements=keys,
        set_={c.name: table.c[c.name] + statement.excluded[c.name]
              for c in table.columns if c.name not in keys},
    )
