"""Where one report's CPU goes, part by part, against raw sqlite3 doing its own row.

Everything here runs with ``synchronous=OFF`` (nothing waits for the disk: the figures are
CPU, best of ``--rounds``), one reporter, on a fresh log on the real disk. The parts:

* the whole report, as shipped (the projections and statistics saved every
  ``SAVE_EVERY_RECORDS`` records), and again with saving put off: the difference is what
  the saves cost per report;
* ``report_command``: the request checked and made the writer's command;
* an empty commit through the writer (``RecordPolicy``: nothing to record): the hand-off to
  the committing thread and the transaction, and that transaction's SQL alone on the
  writer's own connection;
* ``Projector.apply`` of the same records (state machine and statistics fold), in memory;
* what is left: the record itself (its id, JSON, chained hash, the INSERT) and the answer.

Raw sqlite3 (bench/ingest.py's (a): JSON, chained hash, ``uuid4``, one INSERT, one commit)
is measured the same way. Information for issue 20 (docs/performance.md, "Fourteenth
round"); no target here.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

from _common import header, plan, scratch_dir, url_for
from faultledger import FaultLedger, Policy
from faultledger.domain.projector import Projector
from faultledger.domain.statistics import StatsFold
from faultledger.service import writer
from faultledger.service.commands import report_command
from faultledger.service.requests import ReportRequest
from faultledger.store import event_log
from faultledger.store.database import Database
from ingest import Plan, cpu_us, raw_row, run_raw


def best_us(rounds: int, count: int, run: Callable[[], object]) -> float:
    """The lowest process CPU per item over ``rounds`` runs of ``run`` (``count`` items)."""
    best = float("inf")
    for _ in range(rounds):
        start = time.process_time()
        run()
        best = min(best, (time.process_time() - start) / count * 1e6)
    return best


def ledger_parts(work: Plan, rounds: int, db: Path) -> dict[str, float]:
    """CPU per report of faultledger's parts (µs), on one ledger at synchronous=OFF."""
    ledger = FaultLedger.open(url_for(db), policy=Policy())
    parts: dict[str, float] = {}
    try:
        ledger.report("BENCH_WARMUP", "FAILED", severity=2, source_id="/bench/warmup")
        driver = ledger._writer._connection._driver
        driver.execute("PRAGMA synchronous = OFF")

        def report_all() -> None:
            for code, kind, source in work:
                ledger.report(code, kind, severity=2, description="bench", source_id=source)

        parts["whole"] = best_us(rounds, len(work), report_all)
        shipped = writer.SAVE_EVERY_RECORDS
        writer.SAVE_EVERY_RECORDS = 1 << 62  # saving put off (the close saves it all)
        try:
            ledger._writer.save_projections()
            parts["unsaved"] = best_us(rounds, len(work), report_all)
        finally:
            writer.SAVE_EVERY_RECORDS = shipped
        requests = [ReportRequest(code, kind, 2, "bench", source) for code, kind, source in work]
        parts["command"] = best_us(rounds, len(work), lambda: [
            report_command(request) for request in requests])
        nothing = writer.RecordPolicy()  # records nothing once the policy is recorded
        submit = ledger._writer.submit
        parts["empty commit"] = best_us(rounds, len(work), lambda: [
            submit(nothing) for _ in work])

        def transactions() -> None:
            for _ in work:
                driver.execute("BEGIN IMMEDIATE")
                driver.execute("PRAGMA data_version").fetchone()
                driver.execute("COMMIT")

        parts["transaction SQL"] = best_us(rounds, len(work), transactions)
    finally:
        ledger.close()
    db_read = Database(url_for(db), create=False)
    try:
        with db_read.reading() as conn:
            log = list(event_log.read(conn))
    finally:
        db_read.dispose()
    warm = len(log) - len(work)  # the last round's records, applied after all before them
    applied = float("inf")
    for _ in range(rounds):
        projector = Projector(stats=StatsFold())
        projector.apply_all(log[:warm])
        start = time.process_time()
        projector.apply_all(log[warm:])
        applied = min(applied, (time.process_time() - start) / len(work) * 1e6)
    parts["apply"] = applied
    return parts


def raw_parts(work: Plan, rounds: int, scratch: Path) -> dict[str, float]:
    """CPU per row of raw sqlite3's (a) at synchronous=OFF (``ingest.run_raw``): the whole
    row, and building it (JSON, hash, ``uuid4``) without its SQL."""
    whole = min(cpu_us(run_raw(work, scratch / f"raw-{n}.db", fsync=False))
                for n in range(rounds))

    def rows() -> None:
        prev = "0" * 64
        for seq, (code, kind, source) in enumerate(work, 1):
            prev = raw_row(seq, prev, code, kind, source)[-1]

    return {"whole": whole, "row": best_us(rounds, len(work), rows)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--reports", type=int, default=20_000, help="reports per round")
    parser.add_argument("--rounds", type=int, default=3, help="runs of each part (best kept)")
    args = parser.parse_args()
    header("one report's CPU, part by part (synchronous=OFF, best of "
           f"{args.rounds} runs of {args.reports:,})")
    work = plan(args.reports, 200)
    with scratch_dir("parts-") as scratch:
        ours = ledger_parts(work, args.rounds, scratch / "ledger.db")
        raw = raw_parts(work, args.rounds, scratch)
    saves = ours["whole"] - ours["unsaved"]
    hand_off = ours["empty commit"] - ours["transaction SQL"]
    record = ours["unsaved"] - ours["command"] - ours["empty commit"] - ours["apply"]
    lines = [
        ("faultledger, the whole report", ours["whole"]),
        ("  saving projections and statistics (per report)", saves),
        ("  the request checked into a command", ours["command"]),
        ("  the writer's hand-off and bookkeeping", hand_off),
        ("  the transaction's SQL (BEGIN, data_version, COMMIT)", ours["transaction SQL"]),
        ("  state machine and statistics fold (apply)", ours["apply"]),
        ("  the record (id, JSON, hash, INSERT) and the answer", record),
        ("raw sqlite3 (a), the whole row", raw["whole"]),
        ("  its row built (JSON, hash, uuid4)", raw["row"]),
        ("  its SQL (BEGIN, INSERT, COMMIT)", raw["whole"] - raw["row"]),
    ]
    for name, value in lines:
        print(f"   {name:<56} {value:6.2f} µs")
    print(f"   faultledger beyond raw sqlite3: {ours['whole'] - raw['whole']:.2f} µs per report; "
          f"of it the product's own work (saves, checks, apply): "
          f"{saves + ours['command'] + ours['apply']:.2f} µs")


if __name__ == "__main__":
    main()
