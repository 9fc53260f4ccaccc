"""Files the CLI writes (cli/output_files.py) and the database file's mode.

Output files: written to a temporary file of their own, then renamed; never through a
planted symlink; an existing file is kept unless --force; mode 0640; nothing left behind on
failure. The database: created 0600, its -wal/-shm too; an existing file keeps its mode.
Real files, the real CLI in a subprocess.
"""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path

import pytest

from faultledger import FaultLedger
from faultledger.service.output_files import (
    OutputExistsError,
    OutputFileError,
    open_output,
    open_text_output,
    write_output,
)

SHIFT, AS_OF = "2026-11-21/morning", "2026-11-21T20:00:00+00:00"
VICTIM_TEXT = "precious, must never change\n"


def mode(path: Path) -> int:
    return stat.S_IMODE(path.lstat().st_mode)


@pytest.fixture
def umask_022() -> Iterator[None]:
    old = os.umask(0o022)
    try:
        yield
    finally:
        os.umask(old)


@pytest.fixture
def db(tmp_path: Path) -> Path:
    path = tmp_path / "faults.db"
    with FaultLedger.open(f"sqlite:///{path}") as ledger:
        at = datetime(2026, 11, 21, 7, 0, tzinfo=UTC)
        assert ledger.report("MOTOR_OVERHEAT", "FAILED", severity=2, description="92 C",
                             source_id="/motor", at=at).accepted
    return path


@pytest.fixture
def victim(tmp_path: Path) -> Path:
    """A file a planted symlink points to: it must never change."""
    path = tmp_path / "elsewhere" / "victim.txt"
    path.parent.mkdir()
    path.write_text(VICTIM_TEXT)
    return path


def cli(db: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "faultledger.cli.main", *args,
                           "--db", f"sqlite:///{db}"], capture_output=True, text=True,
                          timeout=120)


def assert_refused(done: subprocess.CompletedProcess[str], target: Path) -> None:
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.count("\n") == 1
    assert f"{target} exists" in done.stderr and "--force" in done.stderr


def leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.endswith(".tmp"))


# -- the helper ----------------------------------------------------------------------------------
def test_a_new_file_gets_its_content_and_mode_0640(tmp_path: Path, umask_022: None) -> None:
    target = tmp_path / "out.bin"
    write_output(target, b"data")
    assert target.read_bytes() == b"data"
    assert mode(target) == 0o640
    assert leftovers(tmp_path) == []


def test_an_existing_file_is_kept_without_force_and_replaced_with_it(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(OutputExistsError, match="add --force"):
        write_output(target, "new")
    assert target.read_text() == "old"
    write_output(target, "new", force=True)
    assert target.read_text() == "new" and mode(target) == 0o640
    assert leftovers(tmp_path) == []


def test_a_symlink_at_the_target_is_never_followed(tmp_path: Path, victim: Path) -> None:
    target = tmp_path / "out.txt"
    target.symlink_to(victim)
    with pytest.raises(OutputExistsError, match="symlink"):
        write_output(target, "new")
    assert target.is_symlink() and victim.read_text() == VICTIM_TEXT
    write_output(target, "new", force=True)  # replaces the link itself
    assert not target.is_symlink() and target.read_text() == "new"
    assert victim.read_text() == VICTIM_TEXT


def test_a_dangling_symlink_counts_as_existing(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    target.symlink_to(tmp_path / "would-be-created")
    with pytest.raises(OutputExistsError):
        write_output(target, "new")
    assert not (tmp_path / "would-be-created").exists()


def test_an_error_while_writing_leaves_nothing_behind(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    with pytest.raises(RuntimeError), open_text_output(target) as out:
        out.write("half")
        raise RuntimeError("the export failed")
    assert not target.exists() and leftovers(tmp_path) == []
    target.write_text("old")
    with pytest.raises(RuntimeError), open_output(target, force=True) as raw:
        raw.write(b"half")
        raise RuntimeError("the export failed")
    assert target.read_text() == "old" and leftovers(tmp_path) == []


def test_a_target_that_appears_while_writing_is_not_replaced(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    with pytest.raises(OutputExistsError, match="appeared"), open_output(target) as raw:
        raw.write(b"mine")
        target.write_text("theirs")
    assert target.read_text() == "theirs" and leftovers(tmp_path) == []


def test_a_missing_directory_or_a_directory_target_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(OutputFileError, match=r"cannot write .*No such file or directory"):
        write_output(tmp_path / "no" / "dir" / "out.txt", "x")
    with pytest.raises(OutputFileError, match="is a directory"):
        write_output(tmp_path, "x", force=True)


# -- history --output ----------------------------------------------------------------------------
def test_history_output_never_follows_a_planted_partial_symlink(
    db: Path, tmp_path: Path, victim: Path
) -> None:
    target = tmp_path / "audit.jsonl"
    planted = tmp_path / "audit.jsonl.partial"  # the name older versions wrote through
    planted.symlink_to(victim)
    done = cli(db, "history", "--format", "jsonl", "--output", str(target))
    assert done.returncode == 0, done.stderr
    assert victim.read_text() == VICTIM_TEXT and planted.is_symlink()
    records = [json.loads(line) for line in target.read_text().splitlines()]
    assert [r["kind"] for r in records][-1] == "fault_reported"
    assert mode(target) == 0o640 and not target.is_symlink()
    assert leftovers(tmp_path) == []


def test_history_output_refuses_an_existing_file_or_symlink_without_force(
    db: Path, tmp_path: Path, victim: Path
) -> None:
    target = tmp_path / "audit.csv"
    target.write_text("old export\n")
    assert_refused(cli(db, "history", "--csv", "--output", str(target)), target)
    assert target.read_text() == "old export\n"
    link = tmp_path / "link.csv"
    link.symlink_to(victim)
    assert_refused(cli(db, "history", "--csv", "--output", str(link)), link)
    assert victim.read_text() == VICTIM_TEXT and link.is_symlink()


def test_history_output_with_force_replaces_the_file_or_the_link_itself(
    db: Path, tmp_path: Path, victim: Path
) -> None:
    target = tmp_path / "audit.csv"
    target.write_text("old export\n")
    done = cli(db, "history", "--csv", "--output", str(target), "--force")
    assert done.returncode == 0, done.stderr
    assert target.read_text().startswith("seq,event_id,kind,") and mode(target) == 0o640
    link = tmp_path / "link.csv"
    link.symlink_to(victim)
    done = cli(db, "history", "--csv", "--output", str(link), "--force")
    assert done.returncode == 0, done.stderr
    assert not link.is_symlink() and link.read_text().startswith("seq,")
    assert victim.read_text() == VICTIM_TEXT
    assert leftovers(tmp_path) == []


# -- report-shift --html / --png -----------------------------------------------------------------
@pytest.mark.parametrize("option", ["--html", "--png"])
def test_report_shift_files_are_kept_unless_force(
    db: Path, tmp_path: Path, victim: Path, option: str
) -> None:
    target = tmp_path / f"report{option.replace('--', '.')}"
    target.write_text("old report\n")
    done = cli(db, "report-shift", SHIFT, "--as-of", AS_OF, option, str(target))
    assert_refused(done, target)
    assert done.stdout == ""  # refused before any work: not even the terminal report
    assert target.read_text() == "old report\n"
    link = tmp_path / f"link{option.replace('--', '.')}"
    link.symlink_to(victim)
    assert_refused(cli(db, "report-shift", SHIFT, "--as-of", AS_OF, option, str(link)), link)
    done = cli(db, "report-shift", SHIFT, "--as-of", AS_OF, option, str(link), "--force")
    assert done.returncode == 0, done.stderr
    assert not link.is_symlink() and mode(link) == 0o640
    assert victim.read_text() == VICTIM_TEXT
    done = cli(db, "report-shift", SHIFT, "--as-of", AS_OF, option, str(target), "--force")
    assert done.returncode == 0, done.stderr
    assert target.read_bytes() != b"old report\n" and mode(target) == 0o640
    assert leftovers(tmp_path) == []


def test_report_shift_refuses_both_files_before_writing_either(db: Path, tmp_path: Path) -> None:
    html, png = tmp_path / "r.html", tmp_path / "r.png"
    png.write_bytes(b"old png")
    done = cli(db, "report-shift", SHIFT, "--as-of", AS_OF, "--html", str(html),
               "--png", str(png))
    assert_refused(done, png)
    assert not html.exists() and png.read_bytes() == b"old png"


# -- the database file ---------------------------------------------------------------------------
def test_a_new_database_and_its_wal_are_0600(tmp_path: Path, umask_022: None) -> None:
    path = tmp_path / "new.db"
    with FaultLedger.open(f"sqlite:///{path}") as ledger:
        assert ledger.report("MOTOR_OVERHEAT", "FAILED", severity=2, source_id="/m").accepted
        wal = path.with_name(path.name + "-wal")
        assert wal.exists()
        assert mode(path) == 0o600 and mode(wal) == 0o600
        shm = path.with_name(path.name + "-shm")
        assert not shm.exists() or mode(shm) == 0o600


def test_the_cli_creates_a_database_0600(tmp_path: Path) -> None:
    path = tmp_path / "var" / "faults.db"
    done = subprocess.run([sys.executable, "-m", "faultledger.cli.main", "report", "ESTOP",
                           "FAILED", "--db", f"sqlite:///{path}"], capture_output=True,
                          text=True, timeout=120, umask=0o022)
    assert done.returncode == 0, done.stderr
    assert mode(path) == 0o600


def test_an_existing_database_keeps_its_mode(tmp_path: Path, umask_022: None) -> None:
    path = tmp_path / "shared.db"
    with FaultLedger.open(f"sqlite:///{path}"):
        pass
    path.chmod(0o644)  # an operator chose to share it
    with FaultLedger.open(f"sqlite:///{path}") as ledger:
        assert ledger.report("MOTOR_OVERHEAT", "FAILED", severity=2, source_id="/m").accepted
    assert mode(path) == 0o644


def test_a_read_command_creates_no_database(tmp_path: Path) -> None:
    path = tmp_path / "missing.db"
    done = subprocess.run([sys.executable, "-m", "faultledger.cli.main", "list", "--db",
                           f"sqlite:///{path}"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "does not exist" in done.stderr
    assert not path.exists()
