"""A full disk on a real (small tmpfs) file system: clear refusals while full, nothing
acknowledged lost, and once space is freed the next commits succeed (the WAL is checkpointed
and truncated instead of taking the freed space). Needs root to mount; skipped otherwise."""

from __future__ import annotations

import contextlib
import os
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from faultledger import FaultLedger, Policy

FREED = 256 * 1024


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    mount = tmp_path / "disk"
    mount.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(mount)],
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield mount
    finally:
        for _ in range(50):
            if subprocess.run(["umount", str(mount)], capture_output=True,
                              check=False).returncode == 0:
                break
            time.sleep(0.1)


def fill(path: Path) -> None:
    """Write until the file system says it is full."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
    try:
        with contextlib.suppress(OSError):
            while True:
                os.write(fd, b"\0" * 4096)
    finally:
        os.close(fd)


def test_reports_succeed_again_once_space_is_freed(small_disk: Path) -> None:
    url = f"sqlite:///{small_disk / 'faults.db'}"
    filler = small_disk / "filler"
    with FaultLedger.open(url, policy=Policy()) as ledger:
        acknowledged = [r.seq for r in (ledger.report(f"WARM_{i % 5}", "FAILED", 1, "x" * 200,
                                                      "/probe") for i in range(50))]
        fill(filler)
        refused = None
        for i in range(5_000):
            result = ledger.report(f"FULL_{i % 50}", "FAILED", 1, "x" * 200, "/probe")
            if not result.accepted:
                refused = result
                break
            acknowledged.append(result.seq)
        assert refused is not None, "the disk never filled up"
        assert "cannot grow: the disk or database is full" in refused.message

        os.truncate(filler, filler.stat().st_size - FREED)
        after = [ledger.report(f"AFTER_{i % 30}", "FAILED", 1, "x" * 200, "/probe")
                 for i in range(100)]

        assert [r.accepted for r in after] == [True] * 100, [r.message for r in after
                                                              if not r.accepted][:1]
        acknowledged += [r.seq for r in after]
        stored = {r.seq for r in ledger.history()}
        assert set(acknowledged) <= stored
        assert ledger.verify().ok
    wal = small_disk / "faults.db-wal"
    assert not wal.exists() or wal.stat().st_size < FREED
