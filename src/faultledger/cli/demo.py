"""`faultledger demo`: a scripted scenario showing the debounce life cycle and the audit log.

It runs on a scratch database of its own (a new SQLite file in the temporary directory, kept
so the commands it suggests can look at it) unless ``--db`` names one, and it never writes a
time in the future: its reports are dated one second apart, ending a second before it starts
writing (docs/cli.md, "demo").
"""

from __future__ import annotations

import shlex
import tempfile
from datetime import UTC, datetime, timedelta
from pathlib import Path

from rich.cells import cell_len
from rich.console import Console
from rich.text import Text

from faultledger.cli import render
from faultledger.cli.safe_text import cell, printable
from faultledger.domain.notifications import Notification
from faultledger.domain.policy import Policy
from faultledger.domain.shifts import ShiftCalendar
from faultledger.service.ledger import FaultLedger

DEMO_POLICY = Policy(confirmation_threshold=-3, healing_enabled=True, healing_threshold=3)
CODE = "DEMO_MOTOR_OVERHEAT"
SOURCE = "/robot/motor_left"
STEPS = [("FAILED", "winding temperature 92 C")] * 3 + [("PASSED", "")] * 6
"""The reports, one second apart; then the clear, a second later."""


def scratch_database() -> tuple[Path, str]:
    """A new, empty SQLite file of the demo's own: ``$TMPDIR/faultledger-demo-XXXX/demo.db``."""
    path = Path(tempfile.mkdtemp(prefix="faultledger-demo-")) / "demo.db"
    return path, f"sqlite:///{path}"


def dated_steps(now: datetime) -> list[datetime]:
    """When each step happened: one second apart, the last (the clear) a second before
    ``now``, so no record is dated after the moment it is written."""
    count = len(STEPS) + 1
    return [now - timedelta(seconds=count - i) for i in range(count)]


def run_demo(url: str, out: Console, calendar: ShiftCalendar, width: int | None,
             scratch: Path | None = None, robot_id: str | None = None) -> None:
    out.print(Text.assemble(("faultledger demo", "bold"), " on ",
                            printable(render.describe_url(url))), soft_wrap=True)
    if scratch is not None:
        out.print(cell("a new scratch database of its own (not var/faultledger.db, nor "
                       "--config's or FAULTLEDGER_DB's); it is kept for the commands at the end, "
                       "delete it with:"))
        out.print(cell(f"  rm -r {shlex.quote(str(scratch.parent))}"), soft_wrap=True)
    else:
        out.print(cell("the database given with --db: the demo's records are added to it"))
    out.print("policy: confirm after 3 FAILED (counter -3), heal after the counter reaches +3\n")
    with FaultLedger.open(url, policy=DEMO_POLICY, background=False,
                          robot_id=robot_id) as ledger:
        start = ledger.last_seq
        announced: list[Notification] = []
        ledger.subscribe(announced.append)
        times = dated_steps(datetime.now(UTC))
        for (kind, text), at in zip(STEPS, times, strict=False):
            ledger.report(CODE, kind, severity=2, description=text, source_id=SOURCE, at=at)
            fault = ledger.get_fault(CODE)
            assert fault is not None
            out.print(f"  {kind:<6} from {SOURCE} -> {fault.status.value:<9} "
                      f"counter {fault.debounce_counter:+d}")
            _announce(out, announced)
        result = ledger.clear(CODE, actor="demo:operator", reason="motor replaced",
                              at=times[-1])
        out.print(Text(printable(f"  clear -> {result.message}")))
        _announce(out, announced)
        out.print()
        out.print(render.history_table(
            [r for r in ledger.history(code=CODE) if r.seq > start], calendar, width))
        out.print(render.transitions_table(
            [t for t in ledger.transitions(CODE) if t.seq > start], calendar, width))
        check = ledger.verify()
        out.print(f"\nverify: {'OK' if check.ok else 'FAILED'} ({check.records} records, "
                  f"head hash {check.head_hash[:16]}...)")
    where = "" if scratch is None else f"--db {shlex.quote(str(scratch))}"
    out.print(cell("Try:"))
    for command in ("list --all", f"history --code {CODE}", "verify"):
        line = f"  faultledger {command} {where}".rstrip()
        if cell_len(line) <= out.width:
            out.print(cell(line), soft_wrap=True)
        else:  # a shell continuation: still one command to paste
            out.print(cell(f"  faultledger {command} \\"), soft_wrap=True)
            out.print(cell(f"      {where}"), soft_wrap=True)


def _announce(out: Console, announced: list[Notification]) -> None:
    for n in announced:
        out.print(f"      [magenta]~/events: {n.event_type.value}[/] "
                  f"(status {n.fault.status.value})")
    announced.clear()
