"""Shared fixtures: a ledger on a real database per test, and a notification recorder.

The core suite (every test that takes ``db_url`` or ``open_ledger``) runs on SQLite files by
default and on a real PostgreSQL server with ``--backend postgresql`` (``make test`` runs
both): one server per session (tests/pg_server.py), one fresh database per test. Tests
that need a file (tampering with it, filling the disk) use SQLite paths of their own and
are not collected in the PostgreSQL run.

Every test runs in a working directory of its own (``_isolated_from_the_checkout``): the
relative defaults (``var/faultledger.db``, ``var/http-tokens.yaml``) of a command or server a
test starts then land there, never in the checkout where a user ran ``make run``,
``token create`` or ``demo`` (tests/test_checkout_isolation.py).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from faultledger import FaultLedger, Notification, Policy
from tests import pg_server

ISOLATING_ENV = ("FAULTLEDGER_DB", "FAULTLEDGER_CONFIG")
"""The user's own environment choices, which a test must not inherit."""


@pytest.fixture(scope="session", autouse=True)
def _session_directory(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Class- and session-scoped fixtures (a shared fault manager) start in a scratch
    directory too, and without the user's FAULTLEDGER_DB / FAULTLEDGER_CONFIG."""
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(tmp_path_factory.mktemp("cwd"))
        for name in ISOLATING_ENV:
            patch.delenv(name, raising=False)
        yield


@pytest.fixture(autouse=True)
def _isolated_from_the_checkout(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each test in its own empty working directory, beside its tmp_path (whose contents
    some tests list)."""
    work = tmp_path.with_name(tmp_path.name + "-cwd")
    work.mkdir(exist_ok=True)
    monkeypatch.chdir(work)
    for name in ISOLATING_ENV:
        monkeypatch.delenv(name, raising=False)


BACKENDS = ("sqlite", "postgresql")
BACKEND_FIXTURES = {"db_url", "open_ledger", "fresh_url", "postgres"}
"""A test that takes one of these runs on the backend chosen by ``--backend``."""


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--backend", choices=BACKENDS, default="sqlite",
                     help="database of the core suite: sqlite (files) or postgresql (a real "
                          "PostgreSQL 15 server started for the session)")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "sqlite_only: needs a SQLite file, even in the core "
                                       "suite")
    config.addinivalue_line("markers", "alone: compares latencies within the machine's load; "
                                       "`make` runs it after the others, with no workers "
                                       "beside it (docs/testing.md)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """With ``--backend postgresql`` only the core suite runs (the rest ran on SQLite)."""
    if config.getoption("--backend") != "postgresql":
        return
    keep: list[pytest.Item] = []
    drop: list[pytest.Item] = []
    for item in items:
        fixtures = set(getattr(item, "fixturenames", ()))
        core = bool(fixtures & BACKEND_FIXTURES) and item.get_closest_marker("sqlite_only") is None
        (keep if core else drop).append(item)
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep


@pytest.fixture(scope="session")
def backend(request: pytest.FixtureRequest) -> str:
    return str(request.config.getoption("--backend"))


@pytest.fixture(scope="session")
def postgres_server(backend: str) -> Iterator[pg_server.PostgresServer]:
    """The session's PostgreSQL server (started on first use, in any run)."""
    with pg_server.running() as server:
        yield server


@pytest.fixture
def postgres(postgres_server: pg_server.PostgresServer) -> pg_server.PostgresServer:
    """The session's PostgreSQL server for a test that needs PostgreSQL itself."""
    return postgres_server


@pytest.fixture
def fresh_url(backend: str, tmp_path: Path, request: pytest.FixtureRequest
              ) -> Callable[[str], str]:
    """Factory: fresh_url(name) is the URL of a new empty log on the chosen backend."""

    def _make(name: str = "faults") -> str:
        if backend == "postgresql":
            server: pg_server.PostgresServer = request.getfixturevalue("postgres_server")
            return server.database()
        return f"sqlite:///{tmp_path / (name + '.db')}"

    return _make


@pytest.fixture
def db_url(fresh_url: Callable[[str], str]) -> str:
    """URL of a fresh log (a SQLite file, or a PostgreSQL database with ``--backend
    postgresql``); every ledger a test opens uses this same database."""
    return fresh_url("faults")


@pytest.fixture
def open_ledger(db_url: str) -> Iterator[Callable[..., FaultLedger]]:
    """Factory: open_ledger(policy) opens (or reopens) the test's database file.

    Ledgers still open at the end of the test are closed; a test that reopens the file closes
    the earlier ledger itself.
    """
    opened: list[FaultLedger] = []

    def _open(policy: Policy | None = None) -> FaultLedger:
        ledger = FaultLedger.open(db_url, policy=policy)
        opened.append(ledger)
        return ledger

    yield _open
    for ledger in reversed(opened):
        with contextlib.suppress(Exception):  # already closed by the test
            ledger.close()


@pytest.fixture
def notifications() -> Callable[[FaultLedger], list[Notification]]:
    """Factory: notifications(ledger) subscribes and returns the list the events land in."""

    def _subscribe(ledger: FaultLedger) -> list[Notification]:
        received: list[Notification] = []
        ledger.subscribe(received.append)
        return received

    return _subscribe
