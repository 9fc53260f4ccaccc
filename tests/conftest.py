"""Shared fixtures: a ledger on a real SQLite file per test, and a notification recorder.

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


@pytest.fixture
def db_url(tmp_path: Path) -> str:
    """URL of a fresh SQLite file; every ledger a test opens uses this same file."""
    return f"sqlite:///{tmp_path / 'faults.db'}"


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
