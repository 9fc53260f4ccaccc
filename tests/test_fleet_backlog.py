"""When a central projects the robot logs it stored records of (service/fleet_backlog.py):
after pushes pause, at once past the lag limit, before every read, and again after a failure."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from faultledger.service.fleet_backlog import Backlog


class Projections:
    """The projecting side, recording which logs it was asked to bring up and when."""

    def __init__(self, fail: int = 0) -> None:
        self.calls: list[tuple[int, float]] = []
        self.fail = fail
        self.done = threading.Event()

    def project(self, chain_id: int) -> None:
        if self.fail:
            self.fail -= 1
            raise RuntimeError("database away")
        self.calls.append((chain_id, time.monotonic()))
        self.done.set()


@pytest.fixture
def projections() -> Projections:
    return Projections()


@pytest.fixture
def backlog(projections: Projections) -> Iterator[Backlog]:
    made = Backlog(projections.project, lambda: [], quiet=0.2, max_lag=1_000)
    yield made
    made.close()


def test_logs_are_projected_once_pushes_pause(backlog: Backlog,
                                              projections: Projections) -> None:
    stored_at = time.monotonic()
    backlog.stored(1, 10)
    backlog.stored(2, 30)
    assert backlog.behind() == {1: 10, 2: 30}
    deadline = time.monotonic() + 5
    while len(projections.calls) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert sorted(c for c, _ in projections.calls) == [1, 2]
    assert min(at for _, at in projections.calls) >= stored_at + 0.2
    assert backlog.behind() == {}


@pytest.fixture
def patient(projections: Projections) -> Iterator[Backlog]:
    """A backlog whose pause is far longer than any test here."""
    made = Backlog(projections.project, lambda: [], quiet=60, max_lag=1_000)
    yield made
    made.close()


def test_nothing_is_projected_while_pushes_go_on_below_the_lag_limit(
        patient: Backlog, projections: Projections) -> None:
    for _ in range(8):
        patient.stored(1, 100)
        time.sleep(0.05)
    assert projections.calls == [] and patient.behind() == {1: 800}


def test_a_log_past_the_lag_limit_is_projected_while_pushes_go_on(
        patient: Backlog, projections: Projections) -> None:
    patient.stored(1, 400)
    patient.stored(2, 1_000)
    assert projections.done.wait(30)  # long before the minute's pause
    assert [c for c, _ in projections.calls] == [2] and patient.behind() == {1: 400}


def test_a_read_projects_the_log_at_once_and_only_once(
        backlog: Backlog, projections: Projections) -> None:
    backlog.stored(3, 5)
    backlog.current(3)
    assert [c for c, _ in projections.calls] == [3]
    backlog.current(3)
    time.sleep(0.4)
    assert [c for c, _ in projections.calls] == [3]


def test_a_failed_projection_stays_behind_and_is_retried_by_the_read(
        backlog: Backlog) -> None:
    failing = Projections(fail=1)
    made = Backlog(failing.project, lambda: [], quiet=5, max_lag=1_000)
    try:
        made.stored(4, 7)
        with pytest.raises(RuntimeError, match="database away"):
            made.current(4)
        assert made.behind() == {4: 7}
        made.current(4)
        assert [c for c, _ in failing.calls] == [4] and made.behind() == {}
    finally:
        made.close()


def test_logs_found_behind_at_start_are_projected(projections: Projections) -> None:
    made = Backlog(projections.project, lambda: [5, 6], quiet=0.05, max_lag=1_000)
    try:
        assert projections.done.wait(5)
        deadline = time.monotonic() + 5
        while len(projections.calls) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert sorted(c for c, _ in projections.calls) == [5, 6]
    finally:
        made.close()
