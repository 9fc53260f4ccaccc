"""A stream client that was away catches up from the log: ``notifications_after(N)`` equals
what a subscriber received after seq N, and other processes' records are announced too."""

from __future__ import annotations

import time
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faultledger import FaultLedger, Notification

CODES = ("A", "B", "C_D")
step = st.one_of(
    st.tuples(st.just("report"), st.sampled_from(CODES), st.sampled_from(["FAILED", "PASSED"]),
              st.integers(0, 3)),
    st.tuples(st.just("clear"), st.sampled_from(CODES), st.just(""), st.just(0)),
)


def _key(n: Notification) -> tuple[object, ...]:
    return (n.seq, n.event_type, n.fault, n.timestamp_ns)


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(steps=st.lists(step, min_size=1, max_size=40), cut=st.integers(0, 60))
def test_log_derived_notifications_equal_the_live_ones(
        tmp_path: Path, steps: list[tuple[str, str, str, int]], cut: int) -> None:
    url = f"sqlite:///{tmp_path / f'n{time.monotonic_ns()}.db'}"
    with FaultLedger.open(url) as ledger:
        live: list[Notification] = []
        ledger.subscribe(live.append)
        for kind, code, event_type, severity in steps:
            if kind == "report":
                ledger.report(code, event_type, severity, "d", "/src")
            else:
                ledger.clear(code)
        derived = ledger.notifications_after(cut)
        assert [_key(n) for n in derived] == [_key(n) for n in live if n.seq > cut]
        # Paged: the first page of two, then the rest from its last seq.
        first = ledger.notifications_after(cut, limit=2)
        rest = ledger.notifications_after(first[-1].seq) if first else []
        assert [_key(n) for n in first + rest] == [_key(n) for n in derived]


def test_many_codes_fall_back_to_a_full_replay(tmp_path: Path) -> None:
    with FaultLedger.open(f"sqlite:///{tmp_path / 'f.db'}") as ledger:
        live: list[Notification] = []
        ledger.subscribe(live.append)
        for i in range(520):  # more codes than the selective replay takes
            ledger.report(f"CODE_{i}", "FAILED", 3, "", "/s")
        assert [_key(n) for n in ledger.notifications_after(5, limit=10_000)] == [
            _key(n) for n in live if n.seq > 5]


def test_other_processes_records_are_announced_by_a_serving_ledger(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'shared.db'}"
    with FaultLedger.open(url, background=True) as server:
        heard: list[Notification] = []
        server.subscribe(heard.append)
        with FaultLedger.open(url) as other:
            other.report("OTHER", "FAILED", 3, "", "/x")
            other.clear("OTHER")
        deadline = time.monotonic() + 5
        while len(heard) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert [(n.fault.fault_code, n.event_type.value) for n in heard] == [
            ("OTHER", "fault_confirmed"), ("OTHER", "fault_cleared")]
        assert [_key(n) for n in server.notifications_after(0)] == [_key(n) for n in heard]


def test_bad_arguments_are_refused(tmp_path: Path) -> None:
    import pytest

    from faultledger import InvalidInputError
    with FaultLedger.open(f"sqlite:///{tmp_path / 'b.db'}") as ledger:
        for bad in (-1, True, "3"):
            with pytest.raises(InvalidInputError):
                ledger.notifications_after(bad)  # type: ignore[arg-type]
        with pytest.raises(InvalidInputError):
            ledger.notifications_after(0, limit=-1)
