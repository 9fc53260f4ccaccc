"""The ledger writes no file but its database's own: SQLite's temporary storage stays in
memory. Before, a group commit's multi-row INSERT spilled its statement journal to a new
file in the temporary directory (created, written, unlinked) every few dozen reports; on a
robot whose root file system is read-only that directory may not even be writable.

SQLite reads ``SQLITE_TMPDIR`` once, when the library starts, so the reports run in a child
process. A file created and unlinked there still changes the directory's mtime."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

CHILD = textwrap.dedent("""
    import sys
    from faultledger import FaultLedger, Policy, ReportRequest

    ledger = FaultLedger.open(sys.argv[1], policy=Policy())
    for burst in range(3):
        results = ledger.report_many([
            ReportRequest(f"MOTOR_{i % 200:03d}", "FAILED" if (i + burst) % 3 else "PASSED",
                          2, "overcurrent", f"/robot/joint_{i % 7}")
            for i in range(600)])
        assert all(result.accepted for result in results), results
    ledger.close()
    print("done")
""")


def test_reports_in_bursts_create_no_temporary_file(tmp_path: Path) -> None:
    temporary = tmp_path / "sqlite-tmp"
    temporary.mkdir()
    os.utime(temporary, (1_000_000_000, 1_000_000_000))  # any change will show
    database = tmp_path / "ledger.db"
    env = {**os.environ, "SQLITE_TMPDIR": str(temporary)}
    done = subprocess.run([sys.executable, "-c", CHILD, f"sqlite:///{database}"], env=env,
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "done"
    assert database.stat().st_size > 0  # the reports went to the database
    assert list(temporary.iterdir()) == []
    assert temporary.stat().st_mtime == 1_000_000_000, "a temporary file came and went"
