"""Projections saved behind the commits (docs/architecture.md, "Saving the projections"): every
reader, in this process or another, sees every acknowledged report; two writers that save in
turn leave projections equal to a full replay; a long run saves as it goes."""

from __future__ import annotations

import time
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from faultledger import FaultLedger, Policy
from faultledger.service import restore, writer
from faultledger.store.database import Database

START = datetime(2026, 11, 20, 8, 0, tzinfo=UTC)
RANGE = ("2026-11-20T00:00:00+00:00", "2026-11-21T00:00:00+00:00")


def report(ledger: FaultLedger, n: int, first: int = 0, codes: int = 7) -> None:
    for i in range(first, first + n):
        result = ledger.report(f"SAVE_{i % codes}", "FAILED" if i % 3 else "PASSED", 2, "",
                               "/base", at=START + timedelta(seconds=i))
        assert result.accepted, result.message


def figures(ledger: FaultLedger) -> list[dict[str, Any]]:
    return [row.as_dict() for row in ledger.stats("hour", *RANGE, as_of=START + timedelta(1))]


def saved_seq(url: str) -> int:
    db = Database(url)
    try:
        with db.reading() as conn:
            return restore.saved_seq(conn)
    finally:
        db.dispose()


def replayed_figures(url: str, tmp_path: Path) -> list[dict[str, Any]]:
    """The figures of a full replay: rebuild a copy of the database, then read."""
    copy = tmp_path / "replayed.db"
    copy.write_bytes(Path(url.removeprefix("sqlite:///")).read_bytes())
    with FaultLedger.open(f"sqlite:///{copy}", background=False) as replayed:
        replayed.rebuild()
        return figures(replayed)


def test_a_reader_sees_every_report_before_the_writer_saved_its_projections(
        tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'log.db'}"
    with FaultLedger.open(url, policy=Policy(confirmation_threshold=-2),
                          background=False) as writer_a:
        report(writer_a, 40)
        assert saved_seq(url) < writer_a.last_seq  # behind the commits, not in them
        with FaultLedger.open(url, background=False) as reader:  # another process's view
            assert reader.last_seq == writer_a.last_seq
            assert reader.all_faults() == writer_a.all_faults()
            assert figures(reader) == figures(writer_a)
            report(writer_a, 10, first=40)
            # The reader catches up with what the writer has not saved either.
            assert figures(reader) == figures(writer_a)
            assert len(reader.transitions()) == len(writer_a.transitions())
        assert writer_a.verify().ok
        expected = figures(writer_a)
    assert replayed_figures(url, tmp_path) == expected


def test_two_writers_saving_in_turn_leave_the_projections_of_a_full_replay(
        tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'log.db'}"
    policy = Policy(confirmation_threshold=-2, healing_enabled=True, healing_threshold=2)
    with FaultLedger.open(url, policy=policy, background=False) as a, \
            FaultLedger.open(url, policy=policy, background=False) as b:
        for round_ in range(6):
            report(a, 7, first=round_ * 20)
            report(b, 5, first=round_ * 20 + 7, codes=5)
            if round_ % 2:
                assert figures(a) == figures(b)  # a saves (b's records too) ...
            else:
                b.transitions()  # ... or b does, over what a saved
            a.clear("SAVE_1", actor="test")
        report(a, 3, first=500)
        assert a.verify().ok and b.verify().ok
        expected = figures(a)
        assert figures(b) == expected
    with FaultLedger.open(url, background=False) as reopened:
        assert reopened.verify().ok
        assert figures(reopened) == expected
    assert replayed_figures(url, tmp_path) == expected


def test_a_long_run_saves_as_it_goes_and_a_closed_log_is_saved_whole(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'log.db'}"
    with FaultLedger.open(url, policy=Policy(), background=False) as ledger:
        report(ledger, writer.SAVE_EVERY_RECORDS + 50, codes=30)
        saved = saved_seq(url)
        assert ledger.last_seq - writer.SAVE_EVERY_RECORDS < saved < ledger.last_seq
        last = ledger.last_seq
    assert saved_seq(url) == last


def test_a_serving_process_saves_within_about_a_second(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'log.db'}"
    with FaultLedger.open(url, policy=Policy(), background=True) as ledger:
        report(ledger, 5)
        deadline = datetime.now(UTC) + timedelta(seconds=10)
        while saved_seq(url) < ledger.last_seq:
            assert datetime.now(UTC) < deadline, "the background tick never saved"
            time.sleep(0.05)
