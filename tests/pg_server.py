"""A real PostgreSQL 15 server for the tests: Debian's ``postgresql`` package, started once per
session in a temporary data directory on a loopback port, one database per test from a
template that already holds the schema.

Debian keeps ``initdb`` and ``pg_ctl`` in the server version's own bin directory
(/usr/lib/postgresql/15/bin), not on PATH. The server refuses to run as root, so as root it
runs as the ``postgres`` OS user (which the package creates); as any other user, as that user.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

SERVER_USER = "postgres"
TEMPLATE = "faultledger_template"
SEARCHED_VERSIONS = ("15", "16", "17")


def bin_dir() -> Path | None:
    """The server's bin directory (PG_BIN overrides), None when no server is installed."""
    override = os.environ.get("PG_BIN")
    candidates = [Path(override)] if override else [
        Path(f"/usr/lib/postgresql/{version}/bin") for version in SEARCHED_VERSIONS]
    for candidate in candidates:
        if (candidate / "initdb").is_file() and (candidate / "pg_ctl").is_file():
            return candidate
    return None


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class PostgresServer:
    """One running server; ``database()`` makes a fresh database for one test."""

    def __init__(self, bin_path: Path) -> None:
        self.bin = bin_path
        self.root = Path(tempfile.mkdtemp(prefix="faultledger-pg-"))
        self.data = self.root / "data"
        self.port = free_port()
        self._as_root = os.geteuid() == 0
        self._counter = itertools.count(1)
        self.user = SERVER_USER if self._as_root else pwd.getpwuid(os.geteuid()).pw_name

    def _run(self, *argv: str) -> subprocess.CompletedProcess[str]:
        command = list(argv)
        if self._as_root:
            command = ["runuser", "-u", SERVER_USER, "--", *command]
        return subprocess.run(command, capture_output=True, text=True, timeout=120, check=False,
                              cwd=self.root)

    def start(self) -> None:
        if self._as_root:
            shutil.chown(self.root, SERVER_USER)
        done = self._run(str(self.bin / "initdb"), "-D", str(self.data), "-A", "trust",
                         "-U", self.user, "-E", "UTF8", "--locale", "C.UTF-8", "--no-sync")
        if done.returncode:
            raise RuntimeError(f"initdb failed: {done.stdout}{done.stderr}")
        options = (f"-c listen_addresses=127.0.0.1 -p {self.port} -k {self.root} "
                   "-c max_connections=200 -c shared_buffers=64MB")
        done = self._run(str(self.bin / "pg_ctl"), "-D", str(self.data), "-l",
                         str(self.root / "server.log"), "-o", options, "-w", "-t", "60", "start")
        if done.returncode:
            log = (self.root / "server.log").read_text(errors="replace")[-2000:]
            raise RuntimeError(f"pg_ctl start failed: {done.stdout}{done.stderr}{log}")

    def stop(self) -> None:
        self._run(str(self.bin / "pg_ctl"), "-D", str(self.data), "-m", "immediate", "-w",
                  "stop")
        shutil.rmtree(self.root, ignore_errors=True)

    def url(self, database: str) -> str:
        return f"postgresql+psycopg://{self.user}@127.0.0.1:{self.port}/{database}"

    def execute(self, sql: str) -> None:
        """One statement outside a transaction (CREATE/DROP DATABASE need that)."""
        import psycopg

        with psycopg.connect(f"host=127.0.0.1 port={self.port} user={self.user} "
                             "dbname=postgres", autocommit=True) as conn:
            conn.execute(sql.encode())  # test-made literal SQL

    def make_template(self) -> None:
        """A database at the schema's head: each test's database is a copy (fast)."""
        from faultledger.store import migrate
        from faultledger.store.database import Database

        self.execute(f"CREATE DATABASE {TEMPLATE}")
        db = Database(self.url(TEMPLATE))
        try:
            migrate.ensure_current(db)
        finally:
            db.dispose()

    def database(self, prefix: str = "t") -> str:
        """URL of a new database holding the current schema and no records."""
        name = f"{prefix}_{os.getpid()}_{next(self._counter)}"
        self.execute(f"CREATE DATABASE {name} TEMPLATE {TEMPLATE}")
        return self.url(name)

    def empty_database(self, prefix: str = "e") -> str:
        """URL of a new database without any schema (for migration tests)."""
        name = f"{prefix}_{os.getpid()}_{next(self._counter)}"
        self.execute(f"CREATE DATABASE {name}")
        return self.url(name)


@contextlib.contextmanager
def running() -> Iterator[PostgresServer]:
    found = bin_dir()
    if found is None:
        raise RuntimeError("PostgreSQL is not installed (apt-get install postgresql; "
                           "/usr/lib/postgresql/15/bin/initdb not found)")
    server = PostgresServer(found)
    started = time.monotonic()
    server.start()
    try:
        server.make_template()
        os.environ.setdefault("FAULTLEDGER_TEST_PG_STARTED_S", f"{time.monotonic() - started:.1f}")
        yield server
    finally:
        server.stop()
