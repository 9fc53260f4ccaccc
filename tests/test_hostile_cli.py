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
