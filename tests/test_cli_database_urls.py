"""A database URL faultledger cannot use is refused before anything opens: one line on
stderr naming what to use instead, exit 2, the password hidden, never `internal error`
(exit 70) from a driver import deep inside SQLAlchemy (issue 17).

The real CLI in a subprocess; a URL in --db, in FAULTLEDGER_DB and in a config file.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

from faultledger.errors import ConfigError
from faultledger.service import bootstrap

CLI = [sys.executable, "-m", "faultledger.cli.main"]


def run(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=60,
                          env={**os.environ, **(env or {})})


def assert_refused(done: subprocess.CompletedProcess[str], *words: str) -> None:
    assert done.returncode == 2, (done.returncode, done.stderr)
    assert done.stdout == ""
    assert "Traceback" not in done.stderr and "internal error" not in done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), done.stderr
    assert "secret" not in done.stderr
    for word in words:
        assert word in done.stderr, done.stderr


OTHER_DATABASES = [
    ("mysql://fleet:secret@db.example/faults", "unsupported database 'mysql'"),
    ("mysql+pymysql://fleet:secret@db.example/faults", "unsupported database 'mysql'"),
    ("mariadb://fleet:secret@db.example/faults", "unsupported database 'mariadb'"),
    ("oracle://fleet:secret@db.example/faults", "unsupported database 'oracle'"),
    ("mssql+pyodbc://fleet:secret@db.example/faults", "unsupported database 'mssql'"),
]


@pytest.mark.parametrize(("url", "words"), OTHER_DATABASES, ids=lambda v: v.split(":")[0])
def test_another_database_kind_is_refused_in_one_line(url: str, words: str) -> None:
    assert_refused(run("list", "--db", url), words, "sqlite:///FILE", "postgresql+psycopg")


@pytest.mark.parametrize("command", [("report", "X", "FAILED"), ("history",),
                                     ("db", "upgrade"), ("stats",), ("demo",)])
def test_every_command_refuses_it(command: tuple[str, ...]) -> None:
    assert_refused(run(*command, "--db", OTHER_DATABASES[0][0]), "unsupported database")


@pytest.mark.parametrize("url", ["sqlite+aiosqlite:///x.db", "postgresql+asyncpg://u:secret@h/d"])
def test_an_asyncio_driver_is_refused(url: str) -> None:
    assert_refused(run("list", "--db", url), "cannot be used", "asyncio")


@pytest.mark.skipif(importlib.util.find_spec("psycopg2") is not None,
                    reason="psycopg2 is installed")
def test_a_driver_that_is_not_installed_is_refused() -> None:
    assert_refused(run("list", "--db", "postgresql+psycopg2://u:secret@h/d"),
                   "psycopg2 driver cannot be used", "postgresql+psycopg://")


def test_the_environment_and_the_config_are_checked_too(tmp_path: Path) -> None:
    assert_refused(run("list", env={"FAULTLEDGER_DB": "mysql://u:secret@h/d"}),
                   "unsupported database 'mysql'")
    config = tmp_path / "faultledger.yaml"
    config.write_text("database:\n  url: mysql://u:secret@h/d\n", encoding="utf-8")
    assert_refused(run("list", "--config", str(config)), "unsupported database 'mysql'")


def test_sqlite_urls_and_paths_still_work(tmp_path: Path) -> None:
    for db in (f"sqlite:///{tmp_path / 'a.db'}", f"sqlite+pysqlite:///{tmp_path / 'b.db'}",
               str(tmp_path / "c.db")):
        done = run("report", "URL_OK", "FAILED", "--db", db)
        assert done.returncode == 0, done.stderr
        assert run("list", "--db", db, "--json").returncode == 0


@pytest.mark.parametrize("url", [url for url, _ in OTHER_DATABASES])
def test_database_url_raises_a_config_error(url: str) -> None:
    with pytest.raises(ConfigError, match="unsupported database"):
        bootstrap.database_url(url)
    assert bootstrap.database_url("sqlite:///x.db") == "sqlite:///x.db"
