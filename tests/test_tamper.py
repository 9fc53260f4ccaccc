"""SPEC §3 integrity: edits made behind faultledger's back with sqlite3 are found by ``verify``.

A log is built through the API and the ledger closed; then one change is made with the
``sqlite3`` module and both ``FaultLedger.verify()`` and ``faultledger verify --db URL`` must
fail naming the first bad seq.
"""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from faultledger import FaultLedger, Policy, VerifyReport
from faultledger.domain.integrity import record_hash

T0 = datetime(2026, 11, 21, 22, 0, tzinfo=UTC)
CLI = [sys.executable, "-m", "faultledger.cli.main"]
LENGTH = 14
"""build_log's records: the log's identity, the policy, 10 reports, a clear, a report."""


def build_log(db: Path) -> int:
    """A small log through the API (identity and policy records, reports over 3 codes, a
    clear); its length."""
    policy = Policy(confirmation_threshold=-2, healing_enabled=True, healing_threshold=2)
    with FaultLedger.open(f"sqlite:///{db}", policy=policy, background=False) as ledger:
        steps = [
            ("MOTOR_OVERHEAT", "FAILED", 2), ("LIDAR_TIMEOUT", "FAILED", 1),
            ("MOTOR_OVERHEAT", "FAILED", 2), ("ESTOP", "FAILED", 3),
            ("LIDAR_TIMEOUT", "PASSED", 0), ("LIDAR_TIMEOUT", "FAILED", 1),
            ("MOTOR_OVERHEAT", "PASSED", 0), ("LIDAR_TIMEOUT", "FAILED", 1),
            ("ESTOP", "PASSED", 0), ("MOTOR_OVERHEAT", "FAILED", 3),
        ]
        for i, (code, kind, severity) in enumerate(steps):
            result = ledger.report(code, kind, severity=severity, description=f"step {i}",
                                   source_id="/robot/base", at=T0 + timedelta(seconds=i))
            assert result.accepted and result.seq is not None, result.message
        cleared = ledger.clear("ESTOP", actor="test:alice", reason="reset")
        assert cleared.success, cleared.message
        ledger.report("MOTOR_OVERHEAT", "PASSED", source_id="/robot/base",
                      at=T0 + timedelta(seconds=20))
        length = ledger.last_seq
    assert length == LENGTH
    return length


@pytest.fixture
def db(tmp_path: Path) -> Path:
    return tmp_path / "faults.db"


@pytest.fixture
def log_length(db: Path) -> int:
    return build_log(db)


def tamper(db: Path, *statements: tuple[str, tuple[object, ...]]) -> None:
    with sqlite3.connect(db) as conn:
        for sql, params in statements:
            conn.execute(sql, params)
    conn.close()


def payload(db: Path, seq: int) -> str:
    with sqlite3.connect(db) as conn:
        row = conn.execute("SELECT payload FROM events WHERE seq = ?", (seq,)).fetchone()
    conn.close()
    return str(row[0])


def verify(db: Path) -> VerifyReport:
    with FaultLedger.open(f"sqlite:///{db}") as ledger:
        return ledger.verify()


def cli_verify(db: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, "verify", "--db", f"sqlite:///{db}"], capture_output=True,
                          text=True, timeout=60)


def edit_payload(db: Path, seq: int) -> None:
    data = json.loads(payload(db, seq))
    data["description"] = "nothing happened here"
    tamper(db, ("UPDATE events SET payload = ? WHERE seq = ?",
                (json.dumps(data, sort_keys=True, separators=(",", ":")), seq)))


def swap_payloads(db: Path, first: int, second: int) -> None:
    a, b = payload(db, first), payload(db, second)
    tamper(db, ("UPDATE events SET payload = ? WHERE seq = ?", (b, first)),
           ("UPDATE events SET payload = ? WHERE seq = ?", (a, second)))


# (name, tampering, expected first bad seq, words the problem message contains)
Tampering = Callable[[Path, int], None]
CASES: list[tuple[str, Tampering, Callable[[int], int], str]] = [
    ("edit-payload", lambda db, n: edit_payload(db, 5), lambda n: 5, "record 5"),
    ("delete-middle-row",
     lambda db, n: tamper(db, ("DELETE FROM events WHERE seq = ?", (6,))),
     lambda n: 6, "record 6 is missing"),
    ("delete-newest-row",
     lambda db, n: tamper(db, ("DELETE FROM events WHERE seq = ?", (n,))),
     lambda n: n, "deleted"),
    ("swap-payloads", lambda db, n: swap_payloads(db, 3, 8), lambda n: 3, "record 3"),
    ("change-fault-code-column",
     lambda db, n: tamper(db, ("UPDATE events SET fault_code = 'OTHER_CODE' WHERE seq = ?",
                               (7,))),
     lambda n: 7, "record 7"),
    ("change-occurred-at-column",
     lambda db, n: tamper(db, ("UPDATE events SET occurred_at_ns = occurred_at_ns + 1 "
                               "WHERE seq = ?", (4,))),
     lambda n: 4, "record 4"),
    ("insert-row-after-head",
     lambda db, n: tamper(db, (
         "INSERT INTO events SELECT seq + 1, 'a1b2c3d4-0000-4000-8000-000000000000', kind, "
         "fault_code, source_id, payload, occurred_at_ns, recorded_at_ns, schema_version, hash "
         "FROM events WHERE seq = ?", (n,))),
     lambda n: n + 1, "record 15"),
]
CASE_IDS = [c[0] for c in CASES]
# The CLI is checked on the five kinds of tampering an auditor would try first.
CLI_CASES = CASES[:5]
CLI_CASE_IDS = CASE_IDS[:5]


def test_untouched_log_verifies_ok(db: Path, log_length: int) -> None:
    report = verify(db)
    assert report.ok, report.problems
    assert (report.records, report.head_seq, report.first_bad_seq, report.problems) == (
        log_length, log_length, None, [])


def test_cli_verify_of_untouched_log_exits_0(db: Path, log_length: int) -> None:
    done = cli_verify(db)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("OK:")
    assert f"{log_length} records" in done.stdout


@pytest.mark.parametrize(("name", "change", "first_bad", "words"), CASES, ids=CASE_IDS)
def test_verify_names_first_bad_seq(db: Path, log_length: int, name: str, change: Tampering,
                                    first_bad: Callable[[int], int], words: str) -> None:
    change(db, log_length)
    report = verify(db)
    assert not report.ok
    assert report.first_bad_seq == first_bad(log_length), report.problems
    assert any(words in problem for problem in report.problems), report.problems


@pytest.mark.parametrize(("name", "change", "first_bad", "words"), CLI_CASES,
                         ids=CLI_CASE_IDS)
def test_cli_verify_exits_1_naming_first_bad_seq(db: Path, log_length: int, name: str,
                                                 change: Tampering,
                                                 first_bad: Callable[[int], int],
                                                 words: str) -> None:
    change(db, log_length)
    done = cli_verify(db)
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert f"first bad seq: {first_bad(log_length)}" in done.stdout
    assert words in done.stderr
    assert "Traceback" not in done.stderr


def test_verify_detects_rewritten_newest_record_with_recomputed_hash(db: Path,
                                                                     log_length: int) -> None:
    """Editing the head and recomputing its hash keeps the chain valid; the anchor catches it."""
    with sqlite3.connect(db) as conn:
        conn.row_factory = sqlite3.Row
        prev = conn.execute("SELECT hash FROM events WHERE seq = ?", (log_length - 1,)).fetchone()
        row = conn.execute("SELECT * FROM events WHERE seq = ?", (log_length,)).fetchone()
        data = json.loads(row["payload"])
        data["source_id"] = "/robot/forged"
        forged = json.dumps(data, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
        new_hash = record_hash(prev["hash"], row["seq"], row["event_id"], row["kind"],
                               row["fault_code"], "/robot/forged", forged,
                               row["occurred_at_ns"], row["recorded_at_ns"],
                               row["schema_version"])
        conn.execute("UPDATE events SET payload = ?, source_id = ?, hash = ? WHERE seq = ?",
                     (forged, "/robot/forged", new_hash, log_length))
    conn.close()
    report = verify(db)
    assert not report.ok
    assert report.first_bad_seq == log_length, report.problems


def test_tampered_projection_row_is_reported_as_differing_from_replay(db: Path,
                                                                      log_length: int) -> None:
    tamper(db, ("UPDATE faults SET severity = 0, status = 'CLEARED' WHERE fault_code = ?",
                ("MOTOR_OVERHEAT",)))
    report = verify(db)
    assert not report.ok
    assert report.first_bad_seq is None  # the log itself is intact
    assert any("MOTOR_OVERHEAT" in p and "differs from a full replay" in p
               for p in report.problems), report.problems


def test_cli_verify_reports_tampered_projection_and_exits_1(db: Path, log_length: int) -> None:
    tamper(db, ("DELETE FROM faults WHERE fault_code = ?", ("LIDAR_TIMEOUT",)))
    done = cli_verify(db)
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert "LIDAR_TIMEOUT" in done.stderr
    assert "differs from a full replay" in done.stderr


def test_tampered_transitions_table_is_reported(db: Path, log_length: int) -> None:
    tamper(db, ("UPDATE transitions SET cause = 'forged' WHERE seq = "
                "(SELECT MIN(seq) FROM transitions)", ()))
    report = verify(db)
    assert not report.ok
    assert any("transitions" in p for p in report.problems), report.problems
