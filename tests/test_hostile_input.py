"""Hostile input through the Python API: clear refusals, nothing stored, and never a valid
report refused because of another's bad input (issue "Hardening", SPEC §9)."""

from __future__ import annotations

import math
import sqlite3
import threading
from collections.abc import Callable, Iterator
from datetime import UTC, date, datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faultledger import FaultLedger, Policy, ReportRequest
from faultledger.domain.clock import MAX_TIME, MIN_TIME
from faultledger.errors import InvalidInputError
from faultledger.service.statistics import MAX_PERIODS

RANGE = "1970-01-01T00:00:00Z .. 2262-04-11T23:47:16Z"
FAR_FUTURE = datetime(9999, 12, 31, tzinfo=UTC)
FAR_PAST = datetime(1, 1, 1, tzinfo=UTC)


@pytest.fixture
def ledger(tmp_path: Path) -> Iterator[FaultLedger]:
    with FaultLedger.open(f"sqlite:///{tmp_path / 'faults.db'}", policy=Policy()) as opened:
        yield opened


def valid(code: str, i: int = 0) -> ReportRequest:
    return ReportRequest(code, "FAILED", 1, f"report {i}", "/probe")


BAD_REPORTS: list[tuple[ReportRequest, str]] = [
    (ReportRequest("A", "FAILED", 1, "", "/x", at=FAR_FUTURE), "is outside the times the log"),
    (ReportRequest("A", "FAILED", 1, "", "/x", at=FAR_PAST), "is outside the times the log"),
    (ReportRequest("A", "FAILED", 1, "", "/x", at=datetime(1969, 12, 31, tzinfo=UTC)),
     "is outside the times the log"),
    (ReportRequest("A", "FAILED", 1, "", "/x", at=datetime(2026, 1, 1)),  # naive
     "timezone-aware"),
    (ReportRequest("A", "FAILED", 1, "", "/x", at="2026-01-01"), "must be a timezone-aware"),  # type: ignore[arg-type]
    (ReportRequest("A", "PASSED", math.nan, "", "/x"), "severity must be 0 (INFO) to 3"),  # type: ignore[arg-type]
    (ReportRequest("A", "PASSED", math.inf, "", "/x"), "severity must be 0 (INFO) to 3"),  # type: ignore[arg-type]
    (ReportRequest("A", "PASSED", 2**64, "", "/x"), "severity must be 0 (INFO) to 3"),
    (ReportRequest("A", "PASSED", 255, "", "/x"), "severity must be 0 (INFO) to 3"),
    (ReportRequest("A", "FAILED", 1.0, "", "/x"), "severity must be 0 (INFO) to 3"),  # type: ignore[arg-type]
    (ReportRequest("A", "FAILED", 1, "a\x00b", "/x"), "description contains a NUL"),
    (ReportRequest("A", "FAILED", 1, "", "/x\x00y"), "source_id contains a NUL"),
    (ReportRequest("A\x00B", "FAILED", 1, "", "/x"), "invalid character '\\x00'"),
    (ReportRequest(None, "FAILED", 1, "", "/x"), "fault_code must be a string"),  # type: ignore[arg-type]
    (ReportRequest("A", "FAILED", 1, None, "/x"), "description must be a string"),  # type: ignore[arg-type]
    (ReportRequest("A", "FAILED", 1, "", b"/x"), "source_id must be a string"),  # type: ignore[arg-type]
    (ReportRequest("A", 2.5, 1, "", "/x"),  # type: ignore[arg-type]
     "event_type must be FAILED (0) or PASSED (1)"),
    (ReportRequest("A", "FAILED", 1, "", "/x", event_id="x" * 10_000), "event_id must be a UUID"),
]


@pytest.mark.parametrize(("bad", "words"), BAD_REPORTS)
def test_bad_report_is_refused_alone_in_its_batch(ledger: FaultLedger, bad: ReportRequest,
                                                  words: str) -> None:
    results = ledger.report_many([valid("BEFORE"), bad, valid("AFTER")])

    assert [r.accepted for r in results] == [True, False, True]
    assert words in results[1].message
    assert [r.fault_code for r in ledger.history(kinds=["fault_reported"])] == ["BEFORE", "AFTER"]


def test_refusal_messages_are_one_bounded_line(ledger: FaultLedger) -> None:
    huge = "\x1b[2J\n" * 200_000
    results = ledger.report_many([
        ReportRequest("A", huge, 1, "", "/x"),
        ReportRequest("A", "FAILED", huge, "", "/x"),  # type: ignore[arg-type]
        ReportRequest("A", "FAILED", 1, "", "/x", event_id=huge),
    ])

    for result in results:
        assert not result.accepted
        assert len(result.message) < 200, result.message
        assert "\n" not in result.message and "\x1b" not in result.message


def test_out_of_range_report_names_the_range(ledger: FaultLedger) -> None:
    result = ledger.report("A", "FAILED", 1, "", "/x", at=FAR_FUTURE)

    assert result.message == f"at 9999-12-31T00:00:00+00:00 is outside the times the log can " \
                             f"hold ({RANGE})"


def test_extreme_times_inside_the_range_are_stored(ledger: FaultLedger) -> None:
    early = ledger.report("EARLY", "FAILED", 1, "", "/x", at=MIN_TIME)
    late = ledger.report("LATE", "FAILED", 1, "", "/x", at=MAX_TIME)

    assert early.accepted and late.accepted, (early.message, late.message)
    assert [r.occurred_at for r in ledger.history(kinds=["fault_reported"])] == [MIN_TIME,
                                                                                MAX_TIME]
    assert ledger.verify().ok


def test_severity_on_passed_is_checked_as_on_failed(ledger: FaultLedger) -> None:
    ledger.report("A", "FAILED", 1, "", "/x")

    for severity in (-(2**63), -1, 4, 255, 2**63 - 1):
        result = ledger.report("A", "PASSED", severity, "", "/x")
        assert not result.accepted
        assert result.message == f"severity must be 0 (INFO) to 3 (CRITICAL), got {severity}"
    assert ledger.report("A", "PASSED", 3, "", "/x").accepted


def test_clear_refuses_an_out_of_range_time_and_a_nul(ledger: FaultLedger) -> None:
    ledger.report("A", "FAILED", 3, "", "/x")

    late = ledger.clear("A", actor="op", at=FAR_FUTURE)
    nul = ledger.clear("A", actor="op\x00root")

    assert not late.success and "outside the times the log can hold" in late.message
    assert not nul.success and "actor contains a NUL" in nul.message
    assert [r.kind for r in ledger.history()].count("fault_cleared") == 0


def test_concurrent_valid_reports_all_accepted_while_bad_ones_share_their_commits(
        ledger: FaultLedger) -> None:
    """The probe: 805 concurrent reports of which some were bad made 736 valid ones fail."""
    valid_results: list[bool] = []
    bad_results: list[bool] = []
    lock = threading.Lock()
    start = threading.Barrier(12)

    def send_valid(worker: int) -> None:
        start.wait()
        for i in range(60):
            result = ledger.report(f"W{worker}_{i % 7}", "FAILED", 1, "", f"/w{worker}")
            with lock:
                valid_results.append(result.accepted)

    def send_bad(worker: int) -> None:
        start.wait()
        for i in range(60):
            bad, _ = BAD_REPORTS[(worker + i) % len(BAD_REPORTS)]
            [result] = ledger.report_many([bad])
            with lock:
                bad_results.append(result.accepted)

    threads = [threading.Thread(target=send_valid, args=(w,)) for w in range(8)]
    threads += [threading.Thread(target=send_bad, args=(w,)) for w in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()

    assert valid_results == [True] * 480
    assert bad_results == [False] * 240
    assert len(ledger.history(kinds=["fault_reported"])) == 480
    assert ledger.verify().ok


def test_a_command_the_database_refuses_fails_alone(tmp_path: Path) -> None:
    """Last resort: validation missed something and the database itself refuses one record
    (here a real SQLite trigger): the rest of the group is committed, the culprit fails."""
    path = tmp_path / "faults.db"
    with FaultLedger.open(f"sqlite:///{path}", policy=Policy()) as first:
        first.report("SEED", "FAILED", 1, "", "/x")
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TRIGGER poison BEFORE INSERT ON events WHEN NEW.fault_code = "
                      "'POISON' BEGIN SELECT RAISE(ABORT, 'poisoned record'); END")
    with FaultLedger.open(f"sqlite:///{path}", policy=Policy()) as ledger:
        results = ledger.report_many([valid("GOOD_1"), valid("POISON"), valid("GOOD_2")])

        assert [r.accepted for r in results] == [True, False, True], results
        assert "poisoned record" in results[1].message
        codes = [r.fault_code for r in ledger.history(kinds=["fault_reported"])]
        assert codes == ["SEED", "GOOD_1", "GOOD_2"]
        assert ledger.get_fault("POISON") is None
        assert ledger.report("GOOD_3", "FAILED", 1, "", "/x").accepted


# -- queries: bounded and checked before any work -----------------------------------------------

@pytest.mark.parametrize(("kwargs", "words"), [
    ({"until": "9999-12-31"}, "until 9999-12-31T00:00:00+00:00 is outside the times"),
    ({"since": "0001-01-01"}, "since 0001-01-01T00:00:00+00:00 is outside the times"),
    ({"until": FAR_FUTURE}, "is outside the times the log can hold"),
    ({"as_of": FAR_FUTURE}, "as_of 9999-12-31T00:00:00+00:00 is outside"),
    ({"since": "1969-12-31", "until": "1970-01-02"}, "since 1969-12-31T00:00:00+00:00 is outs"),
    ({"until": "9999-12-31/night"}, "outside the times the log can hold"),
    ({"by": "10min", "since": "2000-01-01", "until": "2026-01-01"},
     "the range holds about 1,367,568 periods of 10min, the limit is 60,000"),
    ({"by": "hour", "since": "1970-01-01", "until": "2262-01-01"}, "periods of hour"),
    ({"by": "shift", "since": "1970-01-01", "until": "2262-01-01"},
     "the range holds about 335,188 periods of shift, the limit is 60,000"),
    ({"by": "shift", "since": "2000-01-01", "until": "2055-01-01"},  # just above: cut exactly
     f"the range holds more than {MAX_PERIODS:,} periods of shift"),
    ({"by": "day", "since": "1970-01-01", "until": "2262-01-01"}, "periods of day"),
    ({"by": ["shift"]}, "by must be one of"),
    ({"codes": ["A"] * 10_000}, "codes takes at most 256"),
    ({"codes": ["A" * 100_000]}, "a code pattern exceeds maximum length"),
    ({"codes": ["A\x00"]}, "a code pattern contains a NUL"),
    ({"group_by": "severity" * 1000}, "group_by takes distinct names"),
    ({"group_by": [["code"]]}, "group_by takes distinct names"),
    ({"since": "x" * 1_000_000}, "since: expected a date"),
    ({"since": date(2026, 1, 1)}, "since must be a timezone-aware datetime"),
])
def test_stats_refuses_bad_arguments_with_a_specific_message(ledger: FaultLedger,
                                                             kwargs: dict[str, Any],
                                                             words: str) -> None:
    with pytest.raises(InvalidInputError) as refused:
        ledger.stats(**kwargs)

    assert words in str(refused.value)
    assert len(str(refused.value)) < 300


def test_stats_at_the_edges_of_the_range_answers(ledger: FaultLedger) -> None:
    ledger.report("A", "FAILED", 1, "", "/x", at=datetime(2262, 4, 1, 12, tzinfo=UTC))

    rows = ledger.stats(by="day", since="2262-04-01", until=MAX_TIME,
                        as_of=MAX_TIME)
    first = ledger.stats(by="day", since="1970-01-01", until="1970-01-03")

    assert sum(row.failed_reports for row in rows) == 1
    assert len(first) == 2


def test_stats_default_range_near_the_epoch_starts_at_the_epoch(ledger: FaultLedger) -> None:
    rows = ledger.stats(by="hour", until=MIN_TIME + timedelta(hours=2))

    assert rows[0].period.start == MIN_TIME


@pytest.mark.parametrize(("call", "words"), [
    (lambda lg: lg.history(since=10**30), "since 1000000000000000000000000000000 ns is outside"),
    (lambda lg: lg.history(until=-1), "until -1 ns is outside"),
    (lambda lg: lg.history(since=FAR_FUTURE), "since 9999-12-31T00:00:00+00:00 is outside"),
    (lambda lg: lg.history(since=1.5), "since must be a timezone-aware datetime"),
    (lambda lg: lg.history(limit=-1), "limit must be a whole number of 0 or more"),
    (lambda lg: lg.history(limit=2**70), "limit must be a whole number"),
    (lambda lg: lg.history(from_seq=2**70), "from_seq must be a seq number"),
    (lambda lg: lg.history(codes=["*"] * 1000), "codes takes at most 256 patterns"),
    (lambda lg: lg.history(source="x\x00"), "source contains a NUL"),
    (lambda lg: lg.history(code="A" * 5000), "code exceeds maximum length"),
    (lambda lg: lg.history(kinds=["x" * 10_000]), "unknown record kind"),
    (lambda lg: lg.state_at(10**30), "when must be a seq number of 0 or more"),
    (lambda lg: lg.state_at(-5), "when must be a seq number"),
    (lambda lg: lg.state_at(FAR_FUTURE), "when 9999-12-31T00:00:00+00:00 is outside"),
    (lambda lg: lg.state_at(datetime(2026, 1, 1)), "when must be a timezone-aware datetime"),
    (lambda lg: lg.downtimes(FAR_PAST, FAR_FUTURE), "since 0001-01-01T00:00:00+00:00 is outside"),
    (lambda lg: lg.downtimes(MIN_TIME, MAX_TIME, limit=-3), "limit must be a whole number"),
    (lambda lg: lg.get_fault("A\x1b[2J"), "invalid character '\\x1b'"),
])
def test_queries_refuse_bad_arguments_with_a_specific_message(
        ledger: FaultLedger, call: Callable[[FaultLedger], object], words: str) -> None:
    ledger.report("A", "FAILED", 1, "", "/x")

    with pytest.raises(InvalidInputError) as refused:
        call(ledger)

    assert words in str(refused.value)
    assert "\x1b" not in str(refused.value)


# -- every entry point, random input --------------------------------------------------------------

ANYTHING = st.one_of(
    st.none(), st.booleans(), st.integers(), st.integers(min_value=-(2**80), max_value=2**80),
    st.floats(), st.text(), st.text(alphabet=st.characters(max_codepoint=0x20), max_size=5),
    st.binary(max_size=8),
    st.datetimes(), st.datetimes(timezones=st.just(UTC)),
    st.datetimes(timezones=st.sampled_from([timezone(timedelta(hours=14)),
                                            timezone(timedelta(hours=-12))])),
    st.dates(), st.lists(st.text(max_size=4), max_size=3),
    st.sampled_from(["FAILED", "PASSED", "CONFIRMED", "shift", "10min", "code", "2026-11-21/night",
                     "9999-12-31", "0001-01-01", "A", "*", "fault_cleared"]),
)

CALLS: dict[str, Callable[[FaultLedger, list[Any]], object]] = {
    "report": lambda lg, a: lg.report(*a[:7]),
    "report_many": lambda lg, a: lg.report_many([ReportRequest(*a[:7]), valid("OK")]),
    "clear": lambda lg, a: lg.clear(*a[:4]),
    "lookup_fault": lambda lg, a: lg.lookup_fault(a[0]),
    "lookup_entity": lambda lg, a: lg.lookup_entity(a[0]),
    "get_fault": lambda lg, a: lg.get_fault(a[0]),
    "list_faults": lambda lg, a: lg.list_faults(a[0] if isinstance(a[0], list) else (), None),
    "history": lambda lg, a: lg.history(*a[:6]),
    "state_at": lambda lg, a: lg.state_at(a[0]),
    "stats": lambda lg, a: lg.stats(*a[:5]),
    "downtimes": lambda lg, a: lg.downtimes(*a[:3]),
}
RAISE_ON_BAD_INPUT = {"get_fault", "history", "state_at", "stats", "downtimes"}
"""Query methods whose contract is InvalidInputError for bad arguments; the others answer."""


@settings(max_examples=400, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(sorted(CALLS)), args=st.lists(ANYTHING, min_size=7, max_size=7))
def test_no_exception_but_a_refusal_escapes_any_entry_point(ledger: FaultLedger, name: str,
                                                            args: list[Any]) -> None:
    try:
        result = CALLS[name](ledger, args)
    except InvalidInputError as error:
        assert name in RAISE_ON_BAD_INPUT, f"{name} raised {error}"
        assert len(str(error)) < 400
    else:
        if name == "report_many":
            assert isinstance(result, list) and result[-1].accepted, result

    after = ledger.report("STILL_SERVING", "FAILED", 1, "", "/probe")
    assert after.accepted, after.message
