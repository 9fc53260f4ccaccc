"""Eight writer processes on one database, some killed with SIGKILL mid-write (SPEC §11).

Each child opens the same log as a serving writer (with a policy, so it records the policy,
reclassifies and runs the background catch-up) and reports from two threads with
caller-chosen event_ids, printing one line per acknowledgement. Three of them are killed
with SIGKILL while writing, and two more writers start while the others are busy (their
open restores a log that grows underneath). Afterwards: every acknowledged report is in the
log under the seq it was answered, the seqs have no gap, nobody was refused, and ``verify``
(hash chain, projections and statistics equal to a full replay) is OK.

Runs on SQLite and, with ``--backend postgresql``, on a real PostgreSQL server: the case
that corrupted PostgreSQL projections before the write lock existed there.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

from sqlalchemy import create_engine, text

from faultledger import FaultLedger, Policy

WRITERS = 8
LATE_WRITERS = 2
KILLED = 3
REPORTS_PER_WRITER = 150
TIMEOUT_S = 240

CHILD = textwrap.dedent(
    """
    import random, sys, threading, uuid
    from faultledger import FaultLedger, Policy

    url, name, count = sys.argv[1], sys.argv[2], int(sys.argv[3])
    ledger = FaultLedger.open(url, policy=Policy(confirmation_threshold=-2))
    out = threading.Lock()

    def emit(line):
        with out:
            sys.stdout.write(line + "\\n")
            sys.stdout.flush()

    def worker(n):
        rng = random.Random(f"{name}-{n}")
        for i in range(count // 2):
            event_id = str(uuid.uuid4())
            code = "SHARED_%02d" % rng.randrange(12)
            kind = "FAILED" if rng.random() < 0.7 else "PASSED"
            r = ledger.report(code, kind, 1, "", "/" + name, event_id=event_id)
            if r.accepted and r.seq is not None and r.event_id == event_id:
                emit("R %d %s" % (r.seq, event_id))
            else:
                emit("X %s %s" % (code, r.message))

    threads = [threading.Thread(target=worker, args=(n,)) for n in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    ledger.close()
    emit("DONE")
    """
)


class Child:
    def __init__(self, script: Path, url: str, name: str, stderr: Path) -> None:
        self.name = name
        self.lines: list[str] = []
        self._stderr = stderr.open("wb")
        self.process = subprocess.Popen(
            [sys.executable, str(script), url, name, str(REPORTS_PER_WRITER)],
            stdout=subprocess.PIPE, stderr=self._stderr)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for raw in self.process.stdout:
            self.lines.append(raw.decode().strip())

    def acks(self) -> int:
        return sum(1 for line in list(self.lines) if line.startswith("R "))

    def finish(self) -> None:
        try:
            self.process.wait(timeout=TIMEOUT_S)
        finally:
            if self.process.poll() is None:
                self.process.kill()
                self.process.wait()
            self._reader.join(timeout=10)
            self._stderr.close()


    def errors(self) -> str:
        return Path(self._stderr.name).read_text(errors="replace")[-2000:]

    def wait_for_acks(self, count: int) -> None:
        deadline = time.monotonic() + TIMEOUT_S
        while self.acks() < count:
            if self.process.poll() is not None or time.monotonic() > deadline:
                raise AssertionError(f"{self.name} stopped after {self.acks()} "
                                     f"acknowledgements: {self.errors()}")
            time.sleep(0.01)


def test_eight_writers_some_killed_keep_one_gap_free_verified_log(db_url: str,
                                                                  tmp_path: Path) -> None:
    script = tmp_path / "writer.py"
    script.write_text(CHILD)
    children = [Child(script, db_url, f"w{n}", tmp_path / f"w{n}.err") for n in range(WRITERS)]
    victims = children[:KILLED]
    # Kill each victim once it has had some reports acknowledged (mid-write).
    for victim in victims:
        victim.wait_for_acks(10)
        victim.process.send_signal(signal.SIGKILL)
    late = [Child(script, db_url, f"late{n}", tmp_path / f"late{n}.err")
            for n in range(LATE_WRITERS)]
    for child in children + late:
        child.finish()

    acknowledged: dict[str, int] = {}
    refused: list[str] = []
    for child in children + late:
        for line in child.lines:
            if line.startswith("R "):
                _, seq, event_id = line.split()
                acknowledged[event_id] = int(seq)
            elif line.startswith("X "):
                refused.append(f"{child.name}: {line}")
    survivors = children[KILLED:] + late
    for child in survivors:
        assert child.lines[-1:] == ["DONE"], f"{child.name} did not finish: {child.errors()}"
        assert child.process.returncode == 0, f"{child.name}: {child.errors()}"
    assert refused == []
    assert len(acknowledged) >= len(survivors) * REPORTS_PER_WRITER

    with FaultLedger.open(db_url) as reader:
        records = reader.history()
        report = reader.verify()
    assert report.ok, report.problems
    assert [r.seq for r in records] == list(range(1, len(records) + 1))
    stored = {r.event_id: r.seq for r in records}
    missing = {e: s for e, s in acknowledged.items() if stored.get(e) != s}
    assert missing == {}, f"{len(missing)} acknowledged reports missing or moved"


OPENER = textwrap.dedent(
    """
    import sys
    from faultledger import FaultLedger, Policy

    with FaultLedger.open(sys.argv[1], policy=Policy(confirmation_threshold=-2)) as ledger:
        result = ledger.report("AFTER_UPGRADE", "FAILED", 1, "", "/opener")
        print("OK" if result.accepted else "X " + result.message, flush=True)
    """
)


def test_processes_opening_a_log_whose_statistics_must_be_recomputed_all_open(
        db_url: str, tmp_path: Path) -> None:
    """After an upgrade that resets the statistics (as Alembic 0003 did), the first opens
    recompute them from the log; six processes opening at once must all open and write,
    and the tables must equal a full replay afterwards (once saved, never twice)."""
    with FaultLedger.open(db_url, policy=Policy(confirmation_threshold=-2)) as ledger:
        for n in range(300):
            ledger.report(f"CODE_{n % 9}", "FAILED" if n % 4 else "PASSED", 1, "", "/setup")
    engine = create_engine(db_url)
    with engine.begin() as conn:  # what an upgrade that adds statistics leaves behind
        conn.execute(text("UPDATE checkpoints SET seq = 0 WHERE name = 'statistics'"))
    engine.dispose()
    script = tmp_path / "opener.py"
    script.write_text(OPENER)
    runs = [subprocess.Popen([sys.executable, str(script), db_url], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True) for _ in range(6)]
    answers = [run.communicate(timeout=TIMEOUT_S) for run in runs]
    assert [out.strip() for out, _ in answers] == ["OK"] * 6, [err[-1500:] for _, err in answers]
    with FaultLedger.open(db_url) as reader:
        report = reader.verify()
    assert report.ok, report.problems
