"""`verify` runs SQLite's own integrity check (issue "Hardening", item 5).

The hash chain covers the records, not the b-trees: a flipped byte in an index page leaves the
chain intact while lookups through that index miss rows. Damage is made with real byte flips
in copies of a real database file; SQLite's ``PRAGMA integrity_check``, run directly with the
stdlib module, is the judge of whether a copy is damaged.
"""

from __future__ import annotations

import random
import shutil
import sqlite3
import subprocess
from datetime import timedelta
from pathlib import Path

import pytest

from faultledger import FaultLedger
from tests.test_tamper import CLI, T0, build_log

FLIPS = 40
SEED = 20261121


@pytest.fixture(scope="module")
def populated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A log of a few hundred records over several codes and sources (tables and indexes
    spanning many pages), checkpointed into the main file."""
    path = tmp_path_factory.mktemp("integrity") / "faults.db"
    build_log(path)
    with FaultLedger.open(f"sqlite:///{path}", background=False) as ledger:
        for i in range(300):
            result = ledger.report(f"CODE_{i % 17}", "PASSED" if i % 3 == 0 else "FAILED",
                                   severity=i % 4, description="d" * (i % 40),
                                   source_id=f"/robot/s{i % 5}", at=T0 + timedelta(seconds=i))
            assert result.accepted, result.message
    with sqlite3.connect(path) as conn:
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.close()
    return path


def sqlite_damage(path: Path) -> list[str]:
    """What SQLite's own check says about a file (empty: intact)."""
    try:
        conn = sqlite3.connect(path)
        try:
            found = [str(row[0]) for row in conn.execute("PRAGMA integrity_check")]
        finally:
            conn.close()
    except sqlite3.DatabaseError as error:
        return [str(error)]
    return [] if found == ["ok"] else found


def cli_verify(path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, "verify", "--db", f"sqlite:///{path}"], capture_output=True,
                          text=True, timeout=120)


def test_intact_copy_verifies(populated: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy.db"
    shutil.copy(populated, copy)
    assert sqlite_damage(copy) == []
    done = cli_verify(copy)
    assert done.returncode == 0, done.stderr


def test_damaged_index_with_an_intact_chain_fails_verify(populated: Path,
                                                         tmp_path: Path) -> None:
    """An index entry rewritten: every record and hash is still right, only SQLite's check
    can tell (before it, verify said OK)."""
    copy = tmp_path / "copy.db"
    shutil.copy(populated, copy)
    with sqlite3.connect(copy) as conn:
        page_size = int(conn.execute("PRAGMA page_size").fetchone()[0])
        (root,) = conn.execute("SELECT rootpage FROM sqlite_master WHERE name = "
                               "'ix_transitions_at'").fetchone()
    conn.close()
    with copy.open("r+b") as raw:  # the last byte of the root page: inside its last cell's key
        raw.seek(int(root) * page_size - 1)
        byte = raw.read(1)[0]
        raw.seek(-1, 1)
        raw.write(bytes([byte ^ 0x01]))
    assert sqlite_damage(copy) != []
    with FaultLedger.open(f"sqlite:///{copy}", create=False, upgrade=False,
                          background=False) as ledger:
        report = ledger.verify()
        ranged = ledger.verify(1, ledger.last_seq)
    assert not report.ok
    assert report.problems[0].startswith("SQLite's integrity check found damage")
    assert report.first_bad_seq is None  # not a record: the chain itself is intact
    assert ranged.ok  # a segment reads only its records (documented)
    done = cli_verify(copy)
    assert done.returncode == 1
    assert "integrity check found damage" in done.stderr and "Traceback" not in done.stderr


def test_random_byte_flips_never_verify_ok(populated: Path, tmp_path: Path) -> None:
    size = populated.stat().st_size
    rng = random.Random(SEED)
    damaged = 0
    for flip in range(FLIPS):
        copy = tmp_path / f"flip{flip}.db"
        shutil.copy(populated, copy)
        offset, bit = rng.randrange(100, size), 1 << rng.randrange(8)
        with copy.open("r+b") as raw:
            raw.seek(offset)
            byte = raw.read(1)[0]
            raw.seek(offset)
            raw.write(bytes([byte ^ bit]))
        if sqlite_damage(copy):
            damaged += 1
            done = cli_verify(copy)
            where = f"flip {flip} at offset {offset}: exit {done.returncode}, {done.stderr!r}"
            assert done.returncode != 0, where
            assert "Traceback" not in done.stderr, where
            if done.returncode == 2:
                assert len(done.stderr.strip().splitlines()) == 1, where
        copy.unlink()
    assert damaged >= 5  # the seed must exercise the check, or this test proves nothing
