"""Hostile arguments to the `faultledger` CLI: one clear line and exit 1/2, never a traceback
or an "internal error" (issue "Hardening", SPEC §9)."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faultledger import FaultLedger, Policy
from faultledger.cli.main import main

CLI = [sys.executable, "-m", "faultledger.cli.main"]


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=120,
                          check=False)


@pytest.fixture(scope="module")
def db_url(tmp_path_factory: pytest.TempPathFactory) -> str:
    url = f"sqlite:///{tmp_path_factory.mktemp('cli') / 'faults.db'}"
    with FaultLedger.open(url, policy=Policy()) as ledger:
        for i in range(20):
            ledger.report(f"CODE_{i % 4}", "FAILED" if i % 3 else "PASSED", i % 4,
                          "[/] \x1b[2J", f"/src{i % 2}")
        ledger.clear("CODE_1", actor="op", reason="[bold]x")
    return url


@pytest.mark.parametrize(("args", "words"), [
    (["report", "X", "FAILED", "--at", "9999-12-31T00:00Z"],
     "--at 9999-12-31T00:00:00+00:00 is outside the times the log can hold"),
    (["report", "X", "FAILED", "--at", "9999-12-31T23:59"], "is outside the times the log"),
    (["report", "X", "FAILED", "--at", "0001-01-01T00:00"], "is outside the times the log"),
    (["report", "X", "FAILED", "--at", "1969-07-20T20:17Z"], "is outside the times the log"),
    (["report", "X", "FAILED", "--severity", "99999999999999999999999"], "severity must be 0"),
    (["list", "--at", "99999999999999999999"],
     "--at must be a seq number or an ISO 8601 date or time"),
    (["list", "--at", "9999999999999999999"], "when must be a seq number of 0 or more"),
    (["list", "--at", "²"], "--at must be a seq number or an ISO 8601 date or time"),
    (["stats", "--by", "10min", "--since", "2000-01-01", "--until", "2026-01-01"],
     "the range holds about 1,367,568 periods of 10min, the limit is 60,000"),
    (["stats", "--until", "9999-12-31"], "is outside the times the log can hold"),
    (["history", "--since", "0001-01-01"], "is outside the times the log can hold"),
    (["history", "--from-seq", "99999999999999999999999"], "from_seq must be a seq number"),
    (["state-at", "9999999999999999999"], "seq must be a seq number of 0 or more"),
    (["verify", "--to-seq", "99999999999999999999999"], "to_seq must be a seq number"),
])
def test_bad_argument_is_one_line_and_exit_1_or_2(db_url: str, args: list[str],
                                                  words: str) -> None:
    done = run_cli(*args[:1], "--db", db_url, *args[1:])

    assert done.returncode in (1, 2), (done.stdout, done.stderr)
    assert words in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and "internal error" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_nothing_was_written_by_the_refused_reports(db_url: str) -> None:
    with FaultLedger.open(db_url) as ledger:
        assert ledger.get_fault("X") is None


# -- random arguments, in process (hundreds of runs) -------------------------------------------

COMMANDS = ["report", "list", "show", "clear", "history", "verify", "state-at", "stats",
            "report-shift", "db"]
OPTIONS = ["--at", "--since", "--until", "--by", "--code", "--status", "--severity", "-s",
           "--source", "--kind", "--limit", "--from-seq", "--to-seq", "--group-by", "--as-of",
           "--format", "--json", "--csv", "--all", "--actor", "--reason", "-d", "--description",
           "--shifts", "--wide", "--config", "current", "upgrade"]
VALUES = st.one_of(
    st.sampled_from(["FAILED", "PASSED", "CODE_1", "CODE_*", "9999-12-31", "0001-01-01",
                     "2026-11-21/night", "2026-13-40", "-1", "0", "99999999999999999999999",
                     "shift", "10min", "jsonl", "csv", "table", "[/]", "\x1b[2J", "nan", "inf",
                     "1e308", "2026-11-21T06:00+25:00", "T", "/", "*", "[", "code", "..", ""]),
    st.text(alphabet=st.characters(blacklist_categories=["Cs"], blacklist_characters="\x00"),
            max_size=12),
    st.integers().map(str),
)
ARGV = st.tuples(st.sampled_from(COMMANDS),
                 st.lists(st.one_of(st.sampled_from(OPTIONS), VALUES), max_size=6))


@settings(max_examples=250, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(argv=ARGV)
def test_random_arguments_never_end_in_a_traceback(db_url: str, argv: tuple[str, list[str]],
                                                   capsys: pytest.CaptureFixture[str],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    command, rest = argv
    monkeypatch.setattr(sys, "argv", ["faultledger", command, *rest, "--db", db_url])
    monkeypatch.chdir(Path(db_url.removeprefix("sqlite:///")).parent)
    with pytest.raises(SystemExit) as ended:
        main()
    _out, err = capsys.readouterr()

    assert ended.value.code in (0, 1, 2, None), (command, rest, err)
    assert "Traceback" not in err and "internal error" not in err, (command, rest, err)


@pytest.fixture(autouse=True)
def _no_config(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    monkeypatch.delenv("FAULTLEDGER_CONFIG", raising=False)
    monkeypatch.delenv("FAULTLEDGER_DB", raising=False)
    yield


def test_a_record_that_cannot_be_read_back_is_one_line_and_fails_verify(tmp_path: Path
                                                                         ) -> None:
    """A byte flipped inside a stored payload (not damage SQLite itself sees): opening must
    say so in one line, and `verify` must fail, never an "internal error"."""
    path = tmp_path / "damaged.db"
    with FaultLedger.open(f"sqlite:///{path}", policy=Policy()) as ledger:
        for i in range(5):
            ledger.report(f"CODE_{i}", "FAILED", 1, "", "/x")
    with sqlite3.connect(path) as conn:
        conn.execute("UPDATE events SET payload = substr(payload, 2) WHERE seq = 4")
        conn.execute("UPDATE checkpoints SET seq = 2")  # so that opening replays seq 4

    listed = run_cli("list", "--db", f"sqlite:///{path}")
    verified = run_cli("verify", "--db", f"sqlite:///{path}")

    assert listed.returncode == 2 and verified.returncode == 1, (listed, verified)
    for done in (listed, verified):
        assert "cannot be restored" in done.stderr and "damaged or was edited" in done.stderr
        assert "internal error" not in done.stderr and "Traceback" not in done.stderr
        assert len(done.stderr.strip().splitlines()) == 1


# -- issue 18: shift ids outside the log, anchors that are no file, rehashed damage ----------

@pytest.mark.parametrize("shift", ["9999-12-31/night", "0001-01-01/night", "9999-12-31/morning"])
def test_report_shift_outside_the_log_is_one_line_and_exit_2(db_url: str, shift: str) -> None:
    done = run_cli("report-shift", shift, "--db", db_url)

    assert done.returncode == 2, (done.stdout, done.stderr)
    assert done.stderr.strip() == (f"error: shift {shift} is outside the times the log can "
                                   "hold (1970-01-01T00:00:00Z .. 2262-04-11T23:47:16Z)")


def test_verify_with_dev_zero_as_anchor_or_key_is_exit_2(db_url: str, tmp_path: Path) -> None:
    """/dev/zero never ends: reading it whole was a MemoryError (exit 70)."""
    from faultledger.service.anchors import new_key_pair

    *_, public_pem = new_key_pair()
    public = tmp_path / "anchor.pub"
    public.write_bytes(public_pem)
    as_anchor = run_cli("verify", "--db", db_url, "--anchor", "/dev/zero",
                        "--public-key", str(public))
    as_key = run_cli("verify", "--db", db_url, "--anchor", "/dev/null",
                     "--public-key", "/dev/zero")

    assert (as_anchor.returncode, as_key.returncode) == (2, 2), (as_anchor, as_key)
    assert as_anchor.stderr.strip() == ("error: cannot read anchor /dev/zero: it holds more "
                                        "than 64 KiB (no anchor file is that large)")
    assert as_key.stderr.strip() == ("error: cannot read public key /dev/zero: it holds more "
                                     "than 64 KiB (no public key file is that large)")


def rehash(path: Path) -> None:
    """Recompute every hash and the checkpoint's: an edit a chain check cannot see."""
    from faultledger.domain.integrity import GENESIS_HASH, record_hash

    with sqlite3.connect(path) as conn:
        previous = GENESIS_HASH
        for row in conn.execute("SELECT seq, event_id, kind, fault_code, source_id, payload, "
                                "occurred_at_ns, recorded_at_ns, schema_version FROM events "
                                "ORDER BY seq").fetchall():
            previous = record_hash(previous, *row)
            conn.execute("UPDATE events SET hash = ? WHERE seq = ?", (previous, row[0]))
        conn.execute("UPDATE checkpoints SET hash = ?", (previous,))


@pytest.mark.parametrize(("payload", "error"), [
    ('{"x":1}', "KeyError: 'fault_code'"),
    ("not json", "JSONDecodeError"),
    ('{"description":"","event_type":"MAYBE","fault_code":"CODE_1","severity":1,'
     '"source_id":"/x"}', "KeyError: 'MAYBE'"),
])
def test_verify_of_a_rehashed_malformed_record_fails_naming_its_seq(tmp_path: Path,
                                                                   payload: str,
                                                                   error: str) -> None:
    """A payload this code cannot read, its hash and every later one recomputed: the chain
    is intact, the full replay is not (was exit 70, "internal error")."""
    path = tmp_path / "rehashed.db"
    with FaultLedger.open(f"sqlite:///{path}", policy=Policy()) as ledger:
        for i in range(5):
            ledger.report(f"CODE_{i}", "FAILED", 1, "", "/x")
    with sqlite3.connect(path) as conn:
        conn.execute("UPDATE events SET payload = ? WHERE seq = 3", (payload,))
    rehash(path)

    done = run_cli("verify", "--db", f"sqlite:///{path}")
    as_json = run_cli("verify", "--json", "--db", f"sqlite:///{path}")

    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stderr.startswith("FAILED: record seq 3 cannot be read back (" + error)
    assert "its content is damaged or was edited" in done.stderr
    assert "first bad seq: 3" in done.stdout
    assert "internal error" not in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert as_json.returncode == 1
    assert '"first_bad_seq": 3' in as_json.stdout


def test_a_rehashed_malformed_record_after_the_checkpoint_is_named_when_opening(
        tmp_path: Path) -> None:
    path = tmp_path / "tail.db"
    with FaultLedger.open(f"sqlite:///{path}", policy=Policy()) as ledger:
        for i in range(5):
            ledger.report(f"CODE_{i}", "FAILED", 1, "", "/x")
    with sqlite3.connect(path) as conn:
        conn.execute("UPDATE events SET payload = '{}' WHERE seq = 5")
        conn.execute("UPDATE checkpoints SET seq = 2")  # so that opening replays seq 3..6
    rehash(path)

    verified = run_cli("verify", "--db", f"sqlite:///{path}")
    listed = run_cli("list", "--db", f"sqlite:///{path}")

    assert (verified.returncode, listed.returncode) == (1, 2), (verified, listed)
    assert verified.stderr.startswith("verify FAILED: database ")
    for done in (verified, listed):
        assert "cannot be restored (record seq 5 cannot be read back (KeyError" in done.stderr
        assert "internal error" not in done.stderr and "Traceback" not in done.stderr
