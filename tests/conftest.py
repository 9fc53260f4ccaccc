"""Shared fixtures: a ledger on a real SQLite file per test, and a notification recorder."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from faultledger import FaultLedger, Notification, Policy


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
