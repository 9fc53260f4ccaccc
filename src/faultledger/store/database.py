"""Engine setup (durable SQLite settings) and translation of driver errors into clear ones."""

from __future__ import annotations

import contextlib
import hashlib
import os
import sqlite3
import stat
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from sqlalchemy import Connection, Engine, create_engine, exc
from sqlalchemy.engine import make_url

from faultledger.errors import NotADatabaseError, StoreError
from faultledger.store.dialects import (
    BUSY_TIMEOUT_MS,
    WRITE_LOCK,
    DialectRules,
    presize_wal,
    rules_for,
)

__all__ = ["BUSY_TIMEOUT_MS", "Database", "WriteConnection", "describe", "translate_errors"]

LOW_SPACE_CHECKPOINT_PAGES = 16
"""WAL pages between checkpoints once the disk was full (SQLite's default is 1000, 4 MiB):
each commit appends whole pages to the WAL, so on a nearly full disk the WAL itself would
take the space freed for new records."""
LOW_SPACE_UNTIL_FREE = 64 * 1024 * 1024
"""Free bytes on the database's file system that end the low-space mode."""


def _sqlite_file(url: str) -> Path | None:
    parsed = make_url(url)
    if parsed.get_backend_name() != "sqlite":
        return None
    database = parsed.database or ""
    if not database or database == ":memory:" or database.startswith("file:"):
        return None
    return Path(database)


CENTRAL_POOL = {"pool_size": 16, "max_overflow": 48}
"""PostgreSQL: a fleet central reads and writes its robot logs through its own pool (a
writer holds a connection per robot log it keeps open, docs/fleet.md)."""


def _pool_for(url: str) -> dict[str, int]:
    try:
        return CENTRAL_POOL if make_url(url).get_backend_name() == "postgresql" else {}
    except exc.ArgumentError:
        return {}


def schema_of(url: str) -> str | None:
    """The PostgreSQL schema a URL names (``?options=-csearch_path=NAME``), else None: a
    fleet central keeps each robot log in a schema of its own (store/fleet_log.py)."""
    options = make_url(url).query.get("options")
    text = " ".join(options) if isinstance(options, tuple) else (options or "")
    for word in text.split():
        if word.startswith("-csearch_path="):
            return word.removeprefix("-csearch_path=")
    return None


def write_lock_key(url: str) -> int:
    """One write lock per log: per database, or per schema where a URL names one."""
    schema = schema_of(url)
    if schema is None:
        return WRITE_LOCK
    return int.from_bytes(hashlib.sha256(f"schema:{schema}".encode()).digest()[:8], "big",
                          signed=True)


def describe(url: str) -> str:
    """The URL as shown to an operator (password hidden)."""
    return make_url(url).render_as_string(hide_password=True)


class Database:
    """One engine per URL. SQLite runs in WAL mode with synchronous=FULL: a commit is on disk.

    Write transactions take the log's write lock first (store/dialects.py: SQLite ``BEGIN
    IMMEDIATE``, PostgreSQL an advisory lock), so writers never interleave; readers see one
    consistent snapshot.
    """

    def __init__(self, url: str, create: bool = True) -> None:
        self.url = url
        self.path = _sqlite_file(url)
        if self.path is not None:
            if self.path.is_dir():
                raise NotADatabaseError(f"{self.path} is a directory, not a database file")
            _refuse_empty(self.path)
            if not create and not self.path.exists():
                raise StoreError(f"database file {self.path} does not exist")
            self.path.parent.mkdir(parents=True, exist_ok=True)
            if create:
                _create_private(self.path)
        try:
            self.engine: Engine = create_engine(url, **_pool_for(url))
        except (exc.ArgumentError, exc.NoSuchModuleError) as error:
            raise StoreError(f"invalid database URL {url!r}: {error}") from None
        self.dialect = self.engine.dialect.name
        self.rules: DialectRules = rules_for(self.dialect)
        self.rules.configure(self.engine)
        self.engine.update_execution_options(faultledger_lock_key=write_lock_key(url))
        self._shared = False

    @classmethod
    def within(cls, parent: Database, url: str, schema: str) -> Database:
        """A log in a schema of ``parent``'s PostgreSQL database (a fleet central's robot
        log), through ``parent``'s connection pool: each transaction sets its search_path
        and takes that log's own write lock. No engine and no connections of its own."""
        found = cls.__new__(cls)
        found.url = url
        found.path = None
        found.engine = parent.engine.execution_options(
            faultledger_schema=schema, faultledger_lock_key=write_lock_key(url))
        found.dialect = parent.dialect
        found.rules = parent.rules
        found._shared = True
        return found

    @contextlib.contextmanager
    def reading(self) -> Iterator[Connection]:
        with translate_errors(self.url), self.engine.connect() as conn, conn.begin():
            yield conn

    @contextlib.contextmanager
    def writing(self, lock_key: int | None = None, *, flush: bool = True
                ) -> Iterator[Connection]:
        """One write transaction holding the log's write lock, or another lock of the same
        database where the dialect has several (PostgreSQL: a fleet chain's own lock).

        ``flush=False``: the commit does not wait for the disk (SQLite: synchronous=NORMAL
        for this transaction; PostgreSQL: synchronous_commit off). It is as atomic as any,
        and a crash of the process loses nothing; a power loss may undo it whole, never a
        log record (the log's own commits flush the WAL, and with it every commit before
        them). For state that can be derived again (alert delivery), so the write lock is
        held for microseconds instead of an fsync."""
        with translate_errors(self.url), self.engine.connect() as raw:
            conn = raw.execution_options(faultledger_write=True)
            if lock_key is not None:
                conn = conn.execution_options(faultledger_lock_key=lock_key)
            if flush:
                with conn.begin():
                    yield conn
                return
            with self.rules.unflushed(conn) as relaxed, relaxed.begin():
                yield relaxed

    def dispose(self) -> None:
        if not self._shared:  # a log within another database leaves the pool to it
            self.engine.dispose()


class WriteConnection:
    """The writer's long-lived connection: no pool checkout per group commit."""

    def __init__(self, db: Database, presize: bool = False) -> None:
        self._db = db
        self.presize = presize
        """A serving writer's: give a new SQLite WAL its working size at the first write
        (``dialects.presize_wal``); a one-shot writer's log need not pay 4 MiB for it."""
        self._conn: Connection | None = None
        self._driver: Any = None
        """SQLite: the driver connection whose transactions ``transaction`` runs."""
        self._seen: object = None
        self.low_space = False
        """After "disk full": checkpoint every few pages until the disk has room again."""

    def others_committed(self, conn: Connection) -> bool:
        """Whether another connection committed since this one last looked (SQLite's
        ``PRAGMA data_version``); always True where the database cannot tell cheaply."""
        changed, self._seen = self._db.rules.others_committed(conn, self._seen)
        return changed

    @contextlib.contextmanager
    def transaction(self) -> Iterator[Connection]:
        """One write transaction; on any error the connection is dropped and reopened later.

        On SQLite the transaction is the driver's own (``BEGIN IMMEDIATE`` … ``COMMIT``):
        SQLAlchemy's begin and commit cost ~13 µs per group commit, as much as the rest of
        a small group's Python. SQLAlchemy keeps one transaction open on this connection for
        its whole life, so statements run through it need no begin of their own; nothing else
        commits or rolls back on this connection, and an error drops it (rolling back)."""
        try:
            conn = self._open()
            if self._driver is None:
                with conn.begin():
                    yield conn
            else:
                if not self._driver.in_transaction:
                    self._driver.execute("BEGIN IMMEDIATE")
                yield conn
                self._driver.execute("COMMIT")  # a cached statement; commit() parses it anew
        except BaseException as error:
            self.close()
            translated = translated_error(self._db.url, error)
            if translated is error:
                raise
            raise translated from None

    def _open(self) -> Connection:
        if self._conn is None:
            conn = self._db.engine.connect().execution_options(faultledger_write=True)
            self._conn = conn
            self._checkpoint_every(LOW_SPACE_CHECKPOINT_PAGES if self.low_space else None)
            if self._db.dialect == "sqlite":
                conn.begin()  # issues the first BEGIN IMMEDIATE (store/dialects.py)
                self._driver = conn.connection.driver_connection
                if self.presize and not self.low_space and self._db.path is not None:
                    presize_wal(self._db.path)  # under the write lock just taken
        return self._conn

    def _checkpoint_every(self, pages: int | None) -> None:
        if self._db.dialect == "sqlite" and self._conn is not None:
            driver: Any = self._conn.connection.driver_connection
            driver.execute(f"PRAGMA wal_autocheckpoint = {pages or 1000}")

    def check_space(self) -> None:
        """In low-space mode, leave it once the file system has room again."""
        path = self._db.path
        if not self.low_space or path is None:
            return
        try:
            stat = os.statvfs(path.parent)
        except OSError:
            return
        if stat.f_bavail * stat.f_frsize >= LOW_SPACE_UNTIL_FREE:
            self.low_space = False
            with contextlib.suppress(Exception):
                self._checkpoint_every(None)

    def reclaim(self) -> bool:
        """Copy the WAL into the database and truncate it (after "disk full": the WAL only
        grows until a checkpoint, so freed space alone would let a few commits through), and
        checkpoint often from now on (low-space mode). True when the WAL is now empty; on
        any error it is tried again before the next commit."""
        if self._db.dialect != "sqlite":
            return True
        self.low_space = True
        with contextlib.suppress(Exception):
            self._checkpoint_every(LOW_SPACE_CHECKPOINT_PAGES)
        try:
            with translate_errors(self._db.url), self._db.engine.connect() as conn:
                driver: Any = conn.connection.driver_connection
                busy, _, _ = driver.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()
        except StoreError:
            return False
        return not busy

    def close(self) -> None:
        self._seen = None
        self._driver = None
        if self._conn is not None:
            with contextlib.suppress(Exception):
                self._conn.close()
            self._conn = None


DATABASE_MODE = 0o600
"""A new database file's mode; SQLite gives its -wal, -shm and -journal files the same."""


def _refuse_empty(path: Path) -> None:
    """An existing regular file of 0 bytes is no database: SQLite would quietly start a new
    log in it (a truncated copy, a file created by mistake), so it is refused like any other
    file that is not a faultledger database. faultledger never leaves one behind itself
    (``_create_private`` puts a file in place only once SQLite has written its header)."""
    try:
        found = path.stat()
    except OSError:
        return  # missing (created below) or unreadable (SQLite says why)
    if stat.S_ISREG(found.st_mode) and found.st_size == 0:
        raise NotADatabaseError(
            f"{path} is an empty file (0 bytes), not a faultledger database; to start a new "
            "log, delete it or name another path")


def _create_private(path: Path) -> None:
    """Create ``path`` with mode 0600 (whatever the umask) before SQLite opens it, so the fault
    log is never readable by other users. The file is made under a temporary name, given
    SQLite's header (WAL mode, as every connection sets) and then linked to ``path``, which
    must not exist: another process never sees it empty (``_refuse_empty``). An existing file
    keeps its mode; a name that exists by the time we look (another process, a symlink) is
    left to SQLite as is."""
    if path.exists():
        return
    temporary = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.new")
    flags = os.O_CREAT | os.O_EXCL | os.O_WRONLY | getattr(os, "O_NOFOLLOW", 0)
    try:
        fd = os.open(temporary, flags, DATABASE_MODE)
        try:
            os.fchmod(fd, DATABASE_MODE)  # exactly 0600: os.open's mode was masked by umask
        finally:
            os.close(fd)
        with contextlib.closing(sqlite3.connect(temporary)) as conn:
            conn.execute("PRAGMA journal_mode = WAL")
        try:
            os.link(temporary, path)
        except FileExistsError:
            raise
        except OSError:  # a file system without hard links: a rename, unless one appeared
            if not path.exists():
                os.replace(temporary, path)
    except FileExistsError:
        return
    except (OSError, sqlite3.Error) as error:
        raise StoreError(f"cannot create database file {path}: "
                         f"{getattr(error, 'strerror', None) or error}") from None
    finally:
        for leftover in ("", "-wal", "-shm"):
            with contextlib.suppress(OSError):
                os.unlink(f"{temporary}{leftover}")


def classify(url: str, error: BaseException) -> StoreError:
    text = str(getattr(error, "orig", None) or error)
    where = f"database {describe(url)}"
    rules = rules_for(make_url(url).get_backend_name())
    return rules.classify(where, text, error) or StoreError(f"{where}: {text}")


@contextlib.contextmanager
def translate_errors(url: str) -> Iterator[None]:
    """Driver exceptions become StoreError subclasses with a message an operator can act on.

    The ingest path runs statements on the driver's own cursor (store/fastpath.py), so the
    driver's exceptions are caught as well as SQLAlchemy's."""
    try:
        yield
    except Exception as error:
        translated = translated_error(url, error)
        if translated is error:
            raise
        raise translated from None


def translated_error(url: str, error: BaseException) -> BaseException:
    """A driver's exception as the StoreError ``translate_errors`` raises; any other, itself."""
    if isinstance(error, exc.DBAPIError | sqlite3.Error) or _is_driver_error(url, error):
        return classify(url, error)
    return error


def _is_driver_error(url: str, error: BaseException) -> bool:
    with contextlib.suppress(Exception):
        return isinstance(error, rules_for(make_url(url).get_backend_name()).driver_errors())
    return False
