"""`faultledger demo` never touches the live database and never writes a future time;
`list --at` and `state-at` say when their table is not what one might expect (issue 17).

The real CLI in a subprocess on real SQLite files; the working directory is the test's own
(tests/conftest.py), so a demo writing to ``var/faultledger.db`` would be seen there.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from faultledger import FaultLedger
from faultledger.domain.clock import from_ns
from tests.test_safe_output import SGR, run_in_terminal

CLI = [sys.executable, "-m", "faultledger.cli.main"]
DEMO_CODE = "DEMO_MOTOR_OVERHEAT"


def run(*args: str, env: dict[str, str] | None = None,
        cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    base = {k: v for k, v in os.environ.items()
            if k not in ("COLUMNS", "FAULTLEDGER_DB", "FAULTLEDGER_CONFIG")}
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=120,
                          env={**base, **(env or {})}, cwd=cwd)


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def scratch_of(output: str) -> Path:
    url = re.search(r"faultledger demo on sqlite:///(\S+)", output)
    assert url, output
    return Path(url.group(1))


# -- demo ----------------------------------------------------------------------------------------
@pytest.fixture(autouse=True)
def _scratch_in_tmp_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The demo's scratch directories land in this test's tmp_path (TMPDIR), not /tmp."""
    (tmp_path / "tmp").mkdir()
    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))


def test_demo_leaves_the_live_database_alone(tmp_path: Path) -> None:
    """The user's case: a fault manager's database with the demo reporter's fault CONFIRMED
    (`make run`), named by FAULTLEDGER_DB and by the config in the working directory."""
    work = tmp_path / "checkout"
    (work / "var").mkdir(parents=True)
    (work / "config").mkdir()
    live = work / "var" / "faultledger.db"
    with FaultLedger.open(f"sqlite:///{live}", background=False) as ledger:
        assert ledger.report(DEMO_CODE, "FAILED", 2, "running reporter", "/demo_reporter").accepted
        live_seq = ledger.last_seq
    (work / "config" / "faultledger.yaml").write_text(
        f"database:\n  url: sqlite:///{live}\n", encoding="utf-8")
    before = digest(live)
    started = datetime.now(UTC)
    done = run("demo", env={"FAULTLEDGER_DB": str(live)}, cwd=work)
    finished = datetime.now(UTC)
    assert done.returncode == 0, done.stderr
    assert digest(live) == before  # not one byte of the live database changed
    with FaultLedger.open(f"sqlite:///{live}", create=False, upgrade=False,
                          background=False) as ledger:
        assert ledger.last_seq == live_seq
        fault = ledger.get_fault(DEMO_CODE)
        assert fault is not None and fault.status.value == "CONFIRMED"
    scratch = scratch_of(done.stdout)
    assert scratch.exists() and scratch != live and not scratch.is_relative_to(work)
    assert scratch.parent.name.startswith("faultledger-demo-")
    assert scratch.parent.parent == tmp_path / "tmp"  # the temporary directory
    assert "scratch database" in done.stdout and "kept" in done.stdout
    assert f"rm -r {scratch.parent}" in done.stdout
    assert f"faultledger list --all --db {scratch}" in done.stdout  # the commands it suggests
    with FaultLedger.open(f"sqlite:///{scratch}", create=False, upgrade=False,
                          background=False) as ledger:
        records = ledger.history()
    assert [r.kind for r in records].count("fault_reported") == 9
    for record in records:  # never dated after it was written, nor after the demo ended
        assert record.occurred_at_ns <= record.recorded_at_ns, record
        assert started - timedelta(seconds=30) < record.occurred_at <= finished
    reported = [r.occurred_at for r in records if r.kind == "fault_reported"]
    assert reported == sorted(reported) and len(set(reported)) == 9  # one second apart
    cleared = [r for r in records if r.kind == "fault_cleared"]
    assert cleared and cleared[0].occurred_at <= finished


def test_two_demos_get_two_scratch_databases(tmp_path: Path) -> None:
    first, second = run("demo", cwd=tmp_path), run("demo", cwd=tmp_path)
    assert first.returncode == 0 and second.returncode == 0, first.stderr + second.stderr
    paths = [scratch_of(first.stdout), scratch_of(second.stdout)]
    assert paths[0] != paths[1] and all(p.exists() for p in paths)
    assert not (tmp_path / "var").exists()
    for output in (first.stdout, second.stdout):  # each its own scenario from seq 1
        assert "verify: OK (12 records" in output  # identity, policy, 9 reports, a clear


def test_demo_with_db_adds_to_that_database_and_says_so(tmp_path: Path) -> None:
    target = tmp_path / "mine.db"
    done = run("demo", "--db", str(target))
    assert done.returncode == 0, done.stderr
    assert "the database given with --db" in done.stdout and "scratch" not in done.stdout
    with FaultLedger.open(f"sqlite:///{target}", create=False, upgrade=False,
                          background=False) as ledger:
        assert ledger.get_fault(DEMO_CODE) is not None
        assert all(r.occurred_at_ns <= r.recorded_at_ns for r in ledger.history())
    assert "faultledger verify\n" in done.stdout  # no --db to add: the user named it


def test_demo_at_80_columns_keeps_kinds_whole() -> None:
    code, raw = run_in_terminal("demo", columns=80)  # a pseudo-terminal 80 columns wide
    shown = SGR.sub("", raw.decode("utf-8").replace("\r\n", "\n"))
    assert code == 0, shown
    table = [line for line in shown.splitlines() if line.startswith(("┃", "│", "┏", "└"))]
    assert table and all(len(line) <= 80 for line in table), shown  # paths may be longer
    assert sum("fault_reported" in line for line in table) == 9, shown
    assert "  faultledger history --code DEMO_MOTOR_OVERHEAT \\\n      --db /" in shown


# -- list --at / state-at notes ------------------------------------------------------------------
@pytest.fixture
def late_db(tmp_path: Path) -> str:
    """Reports sent now about what happened yesterday (the reporter's times): recorded
    after every time of yesterday. Seq 1 is the log's identity, 2 the policy, 3..5 the
    reports."""
    url = f"sqlite:///{tmp_path / 'late.db'}"
    yesterday = datetime.now(UTC) - timedelta(days=1)
    with FaultLedger.open(url, background=False) as ledger:
        for i in range(3):
            assert ledger.report(f"LATE_{i}", "FAILED", 2, "", "/late",
                                 at=yesterday + timedelta(minutes=i)).accepted
    return url


@pytest.mark.parametrize("command", [("list", "--at"), ("state-at",)])
def test_a_table_emptied_by_late_records_says_why(late_db: str, command: tuple[str, ...]
                                                  ) -> None:
    moment = (datetime.now(UTC) - timedelta(days=1) + timedelta(hours=1)).replace(
        microsecond=0)
    done = run(*command, moment.strftime("%Y-%m-%dT%H:%M:%SZ"), "--db", late_db, "--json")
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout)  # the note is on stderr: stdout stays JSON
    faults = data if command[0] == "list" else data["faults"]
    assert faults == []
    [note] = done.stderr.splitlines()
    assert note.startswith("note: the table is by recording time")
    assert "3 records recorded later occurred before it" in note
    # the command that shows what occurred before it (the UTC calendar: +00:00)
    assert f"faultledger history --until {moment.isoformat()}" in note
    assert f"{moment:%Y-%m-%d %H:%M:%S} UTC" in note  # in the calendar's zone, named


def test_list_at_a_seq_past_the_end_says_what_it_shows(late_db: str) -> None:
    done = run("list", "--at", "999", "--db", late_db)
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip() == ("note: seq 999 is past the end of the log (its last seq is "
                                   "5): this is the table after seq 5, the current one")
    assert "faults as of seq 5" in done.stdout
    assert all(f"LATE_{i}" in done.stdout for i in range(3))
    refused = run("state-at", "999", "--db", late_db)  # state-at names a prefix: an error
    assert refused.returncode == 2 and "seq 999 is not in the log" in refused.stderr


def test_a_time_before_the_log_says_nothing_was_recorded(late_db: str) -> None:
    done = run("list", "--at", "2020-01-01", "--db", late_db)
    assert done.returncode == 0, done.stderr
    assert done.stderr.startswith("note: nothing was recorded at or before 2020-01-01 "
                                  "00:00:00 UTC: the log's first record was recorded at ")


def test_no_note_when_the_table_is_what_was_known(late_db: str) -> None:
    time.sleep(0.01)
    now = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    done = run("list", "--at", now, "--db", late_db)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    assert all(f"LATE_{i}" in done.stdout for i in range(3))
    by_seq = run("list", "--at", "3", "--db", late_db)  # up to the first report
    assert by_seq.stderr == "" and "faults as of seq 3" in by_seq.stdout
    assert "LATE_0" in by_seq.stdout and "LATE_1" not in by_seq.stdout


def test_the_recorded_time_of_the_first_record_is_local(late_db: str) -> None:
    with FaultLedger.open(late_db, create=False, upgrade=False, background=False) as ledger:
        first = from_ns(ledger.history(from_seq=1, to_seq=1)[0].recorded_at_ns)
    done = run("state-at", "2020-01-01", "--db", late_db)
    assert f"recorded at {first:%Y-%m-%d %H:%M:%S} UTC" in done.stderr
