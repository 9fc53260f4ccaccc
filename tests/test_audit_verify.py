"""Audit (issue 5): ``verify`` over a seq range and ``faultledger state-at``.

A segment [from, to] is checked from the stored hash of record from - 1: tampering inside it is
found (edited, deleted, inserted, reordered records), tampering outside it is not its business.
The log and the sqlite3 tampering helpers are test_tamper's.
"""

from __future__ import annotations

import json
import sqlite3
import subprocess
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest

from faultledger import FaultLedger, VerifyReport
from faultledger.cli import render
from faultledger.domain.integrity import GENESIS_HASH, record_hash
from faultledger.errors import InvalidInputError
from faultledger.service.audit import seq_recorded_by, seqs_recorded_between
from tests.test_tamper import CLI, LENGTH, build_log, edit_payload, swap_payloads, tamper


@pytest.fixture
def db(tmp_path: Path) -> Path:
    path = tmp_path / "faults.db"
    assert build_log(path) == LENGTH
    return path


def url(db: Path) -> str:
    return f"sqlite:///{db}"


def verify(db: Path, from_seq: int | None = None, to_seq: int | None = None) -> VerifyReport:
    with FaultLedger.open(url(db)) as ledger:
        return ledger.verify(from_seq, to_seq)


def stored_hashes(db: Path) -> dict[int, str]:
    with sqlite3.connect(db) as conn:
        rows = conn.execute("SELECT seq, hash FROM events").fetchall()
    conn.close()
    return {int(seq): str(digest) for seq, digest in rows}


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=60)
    assert "Traceback" not in done.stderr, done.stderr
    return done


def renumber_with_inserted_record(db: Path, at: int) -> None:
    """Insert a forged record at seq ``at``, moving every later record up by one."""
    with sqlite3.connect(db) as conn:
        conn.execute("UPDATE events SET seq = seq + 1000 WHERE seq >= ?", (at,))
        conn.execute("UPDATE events SET seq = seq - 999 WHERE seq >= 1000")
        conn.execute(
            "INSERT INTO events SELECT ?, 'a1b2c3d4-0000-4000-8000-00000000000f', kind, "
            "fault_code, source_id, payload, occurred_at_ns, recorded_at_ns, schema_version, "
            "hash FROM events WHERE seq = ?", (at, at + 1))
    conn.close()


# -- the service API -----------------------------------------------------------------------------
@pytest.mark.parametrize(("from_seq", "to_seq"), [(1, LENGTH), (1, 1), (5, 9), (LENGTH, LENGTH),
                                                  (6, None), (None, 4)])
def test_intact_segment_verifies(db: Path, from_seq: int | None, to_seq: int | None) -> None:
    report = verify(db, from_seq, to_seq)
    first, last = from_seq or 1, to_seq or LENGTH
    assert report.ok, report.problems
    assert (report.records, report.head_seq, report.first_bad_seq, report.problems) == (
        last - first + 1, last, None, [])
    assert report.head_hash == stored_hashes(db)[last]


def test_whole_log_verify_without_arguments_is_unchanged(db: Path) -> None:
    whole = verify(db)
    assert (whole.ok, whole.records, whole.head_seq, whole.first_bad_seq) == (
        True, LENGTH, LENGTH, None)
    assert verify(db, 1, None) == whole  # same chain and checkpoint checks, no projections


Tampering = Callable[[Path], None]
# (name, tampering, range, expected first bad seq or None when the range is unaffected)
CASES: list[tuple[str, Tampering, tuple[int, int | None], int | None]] = [
    ("edit-inside", lambda db: edit_payload(db, 7), (5, 9), 7),
    ("edit-first-of-range", lambda db: edit_payload(db, 5), (5, 9), 5),
    ("edit-last-of-range", lambda db: edit_payload(db, 9), (5, 9), 9),
    ("edit-before-range", lambda db: edit_payload(db, 3), (5, 9), None),
    ("edit-after-range", lambda db: edit_payload(db, 11), (5, 9), None),
    ("edit-anchor-content", lambda db: edit_payload(db, 4), (5, 9), None),
    ("edit-anchor-hash",
     lambda db: tamper(db, ("UPDATE events SET hash = ? WHERE seq = 4", ("f" * 64,))), (5, 9), 5),
    ("edit-column-inside",
     lambda db: tamper(db, ("UPDATE events SET source_id = '/forged' WHERE seq = 6", ())),
     (5, 9), 6),
    ("delete-inside", lambda db: tamper(db, ("DELETE FROM events WHERE seq = 7", ())), (5, 9), 7),
    ("delete-end-of-range",
     lambda db: tamper(db, ("DELETE FROM events WHERE seq IN (8, 9)", ())), (5, 9), 8),
    ("delete-after-range",
     lambda db: tamper(db, ("DELETE FROM events WHERE seq = 11", ())), (5, 9), None),
    ("delete-anchor", lambda db: tamper(db, ("DELETE FROM events WHERE seq = 4", ())), (5, 9), 4),
    ("delete-newest-open-range",
     lambda db: tamper(db, ("DELETE FROM events WHERE seq = ?", (LENGTH,))), (10, None),
     LENGTH),
    ("reorder-inside", lambda db: swap_payloads(db, 6, 8), (5, 9), 6),
    ("reorder-outside", lambda db: swap_payloads(db, 3, 11), (5, 9), None),  # two reports
    ("insert-inside", lambda db: renumber_with_inserted_record(db, 7), (5, 9), 7),
    ("insert-after-range", lambda db: renumber_with_inserted_record(db, 11), (5, 9), None),
    ("insert-after-head",
     lambda db: tamper(db, ("INSERT INTO events SELECT seq + 1, "
                            "'a1b2c3d4-0000-4000-8000-0000000000aa', "
                            "kind, fault_code, source_id, payload, occurred_at_ns, "
                            "recorded_at_ns, schema_version, hash FROM events WHERE seq = ?",
                            (LENGTH,))), (10, None), LENGTH + 1),
]


@pytest.mark.parametrize(("name", "change", "bounds", "first_bad"), CASES,
                         ids=[c[0] for c in CASES])
def test_segment_verify_finds_tampering_inside_and_only_inside(
        db: Path, name: str, change: Tampering, bounds: tuple[int, int | None],
        first_bad: int | None) -> None:
    change(db)
    report = verify(db, *bounds)
    if first_bad is None:
        assert report.ok, report.problems
        assert report.head_hash == stored_hashes(db)[report.head_seq]
    else:
        assert not report.ok
        assert report.first_bad_seq == first_bad, report.problems
        assert report.problems and all(str(first_bad) in p for p in report.problems)
    assert not verify(db).ok  # the whole log always shows it


def test_range_past_the_end_of_the_log_fails(db: Path) -> None:
    report = verify(db, 10, 20)
    assert not report.ok
    assert report.first_bad_seq == LENGTH + 1
    assert f"the log ends at seq {LENGTH}" in report.problems[0]
    starts_late = verify(db, LENGTH + 1)
    assert (starts_late.ok, starts_late.first_bad_seq) == (False, LENGTH + 1)


def test_rewritten_head_with_recomputed_hash_is_caught_by_the_checkpoint(db: Path) -> None:
    with sqlite3.connect(db) as conn:
        conn.row_factory = sqlite3.Row
        prev = conn.execute("SELECT hash FROM events WHERE seq = ?",
                            (LENGTH - 1,)).fetchone()["hash"]
        row = conn.execute("SELECT * FROM events WHERE seq = ?", (LENGTH,)).fetchone()
        forged = row["payload"].replace("/robot/base", "/robot/forged")
        digest = record_hash(prev, LENGTH, row["event_id"], row["kind"], row["fault_code"],
                             "/robot/forged", forged, row["occurred_at_ns"],
                             row["recorded_at_ns"], row["schema_version"])
        conn.execute("UPDATE events SET payload = ?, source_id = ?, hash = ? WHERE seq = ?",
                     (forged, "/robot/forged", digest, LENGTH))
    conn.close()
    report = verify(db, 10, LENGTH)
    assert (report.ok, report.first_bad_seq) == (False, LENGTH)
    assert "differs from the recorded head" in report.problems[0]
    assert verify(db, 10, LENGTH - 1).ok  # the segment before it is still proven by its hashes


@pytest.mark.parametrize(("bounds", "words"), [
    ((0, 5), "from_seq must be a seq number of 1 or more"),
    ((5, 4), "from_seq 5 is after to_seq 4"),
    ((None, -1), "to_seq must be a seq number of 1 or more"),
])
def test_bad_ranges_are_errors(db: Path, bounds: tuple[int | None, int | None],
                               words: str) -> None:
    with FaultLedger.open(url(db)) as ledger, pytest.raises(InvalidInputError, match=words):
        ledger.verify(*bounds)


# -- time -> seq ---------------------------------------------------------------------------------
def build_log_with_a_pause(db: Path) -> tuple[datetime, int]:
    """Records before and after a moment ``mid``; returns it and the last seq before it."""
    length = build_log(db)
    time.sleep(0.01)
    mid = datetime.now(UTC)
    time.sleep(0.01)
    with FaultLedger.open(url(db), background=False) as ledger:
        for code in ("MOTOR_OVERHEAT", "ESTOP"):
            assert ledger.report(code, "FAILED", severity=3, source_id="/robot/arm").accepted
    return mid, length


def test_times_map_to_the_prefix_state_at_replays(tmp_path: Path) -> None:
    db = tmp_path / "faults.db"
    mid, before = build_log_with_a_pause(db)
    with FaultLedger.open(url(db)) as ledger:
        assert seq_recorded_by(ledger, mid) == before
        assert ledger.state_at(mid) == ledger.state_at(before)
        assert seq_recorded_by(ledger, 3) == 3
        assert seqs_recorded_between(ledger, None, mid) == (1, before)
        assert seqs_recorded_between(ledger, mid, None) == (before + 1, None)
        with pytest.raises(InvalidInputError, match="seq 99 is not in the log"):
            seq_recorded_by(ledger, 99)
        with pytest.raises(InvalidInputError, match="no record of the log"):
            seqs_recorded_between(ledger, datetime.now(UTC) + timedelta(days=1), None)


# -- the CLI -------------------------------------------------------------------------------------
def cli_json(*args: str) -> tuple[int, dict[str, Any]]:
    done = run_cli(*args, "--json")
    return done.returncode, json.loads(done.stdout)


def test_cli_verify_segment_ok(db: Path) -> None:
    done = run_cli("verify", "--db", url(db), "--from-seq", "5", "--to-seq", "9")
    assert done.returncode == 0, done.stderr
    hashes = stored_hashes(db)
    assert done.stdout.startswith("OK: records 5..9 (5 records)")
    assert hashes[4] in done.stdout and hashes[9] in done.stdout
    code, data = cli_json("verify", "--db", url(db), "--from-seq", "5", "--to-seq", "9")
    with FaultLedger.open(url(db)) as ledger:
        identity = ledger.identity
    assert code == 0 and identity is not None
    assert data == {"ok": True, "records": 5, "head_seq": 9, "head_hash": hashes[9],
                    "first_bad_seq": None, "problems": [], "from_seq": 5, "to_seq": 9,
                    "anchor_seq": 4, "anchor_hash": hashes[4], "robot_id": identity.robot_id,
                    "ledger_id": identity.ledger_id}
    code, data = cli_json("verify", "--db", url(db), "--to-seq", "3")
    assert (code, data["anchor_hash"], data["records"]) == (0, GENESIS_HASH, 3)


def test_cli_verify_segment_flags_an_edit_inside_not_outside(db: Path) -> None:
    edit_payload(db, 7)
    inside = run_cli("verify", "--db", url(db), "--from-seq", "5", "--to-seq", "9")
    assert inside.returncode == 1, inside.stdout
    assert "first bad seq: 7" in inside.stdout
    assert "record 7 does not match its hash" in inside.stderr
    outside = run_cli("verify", "--db", url(db), "--from-seq", "8", "--to-seq", "13")
    assert outside.returncode == 0, outside.stderr
    assert outside.stdout.startswith("OK: records 8..13")
    whole = run_cli("verify", "--db", url(db))
    assert whole.returncode == 1


def test_cli_verify_by_time(tmp_path: Path) -> None:
    db = tmp_path / "faults.db"
    mid, before = build_log_with_a_pause(db)
    code, data = cli_json("verify", "--db", url(db), "--until", mid.isoformat())
    assert (code, data["ok"], data["from_seq"], data["head_seq"]) == (0, True, 1, before)
    code, data = cli_json("verify", "--db", url(db), "--since", mid.isoformat())
    assert (code, data["ok"], data["from_seq"], data["head_seq"]) == (
        0, True, before + 1, before + 2)
    assert data["anchor_hash"] == stored_hashes(db)[before]


@pytest.mark.parametrize(("args", "words"), [
    (["--from-seq", "3", "--since", "2026-11-21"], "not both"),
    (["--from-seq", "9", "--to-seq", "3"], "--from-seq 9 is after --to-seq 3"),
    (["--until", "yesterday"], "--until must be an ISO 8601 date or time"),
    (["--since", "2099-01-01T00:00Z"], f"no record of the log (seq 1..{LENGTH}) was recorded"),
])
def test_cli_verify_bad_input_exits_2(db: Path, args: list[str], words: str) -> None:
    done = run_cli("verify", "--db", url(db), *args)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert words in done.stderr


def test_cli_state_at_seq(db: Path) -> None:
    code, data = cli_json("state-at", "--db", url(db), "6")
    with FaultLedger.open(url(db)) as ledger:
        expected = [render.fault_dict(f) for f in ledger.state_at(6)]
    assert code == 0
    assert data == {"seq": 6, "hash": stored_hashes(db)[6], "at": None, "faults": expected}
    assert {f["fault_code"] for f in expected} == {"MOTOR_OVERHEAT", "LIDAR_TIMEOUT", "ESTOP"}
    table = run_cli("state-at", "--db", url(db), "6")
    assert table.returncode == 0, table.stderr
    assert "faults as of seq 6" in table.stdout
    assert f"seq 6 hash {stored_hashes(db)[6]}" in table.stdout


def test_cli_state_at_time(tmp_path: Path) -> None:
    db = tmp_path / "faults.db"
    mid, before = build_log_with_a_pause(db)
    code, data = cli_json("state-at", "--db", url(db), mid.isoformat())
    with FaultLedger.open(url(db)) as ledger:
        expected = [render.fault_dict(f) for f in ledger.state_at(mid)]
        now = [render.fault_dict(f) for f in ledger.state_at(ledger.last_seq)]
    assert code == 0
    assert (data["seq"], data["hash"], data["faults"]) == (
        before, stored_hashes(db)[before], expected)
    assert datetime.fromisoformat(data["at"]) == mid
    assert expected != now  # the later reports are not part of that state
    code, data = cli_json("state-at", "--db", url(db), "2000-01-01T00:00Z")
    assert (code, data["seq"], data["hash"], data["faults"]) == (0, 0, GENESIS_HASH, [])


@pytest.mark.parametrize(("when", "words"), [
    ("99", f"seq 99 is not in the log (seq 0..{LENGTH})"),
    ("soon", "WHEN|SEQ must be a seq number or an ISO 8601 date or time"),
    ("-4", "WHEN|SEQ must be a seq number or an ISO 8601 date or time"),
])
def test_cli_state_at_bad_input_exits_2(db: Path, when: str, words: str) -> None:
    done = run_cli("state-at", "--db", url(db), "--", when)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert words in done.stderr
