"""`faultledger demo`: a scripted scenario showing the debounce life cycle and the audit log."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from rich.console import Console
from rich.text import Text

from faultledger.cli import render
from faultledger.cli.safe_text import printable
from faultledger.domain.notifications import Notification
from faultledger.domain.policy import Policy
from faultledger.service.ledger import FaultLedger

DEMO_POLICY = Policy(confirmation_threshold=-3, healing_enabled=True, healing_threshold=3)
CODE = "DEMO_MOTOR_OVERHEAT"


def run_demo(url: str, out: Console) -> None:
    out.print(Text.assemble(("faultledger demo", "bold"), " on ",
                            printable(render.describe_url(url))))
    out.print("policy: confirm after 3 FAILED (counter -3), heal after the counter reaches +3\n")
    with FaultLedger.open(url, policy=DEMO_POLICY, background=False) as ledger:
        start = ledger.last_seq
        announced: list[Notification] = []
        ledger.subscribe(announced.append)
        t0 = datetime.now(UTC)
        steps = (
            [("FAILED", "/robot/motor_left", "winding temperature 92 C")] * 3
            + [("PASSED", "/robot/motor_left", "")] * 6
        )
        for i, (kind, source, text) in enumerate(steps):
            ledger.report(CODE, kind, severity=2, description=text, source_id=source,
                          at=t0 + timedelta(seconds=i))
            fault = ledger.get_fault(CODE)
            assert fault is not None
            out.print(f"  {kind:<6} from {source} -> {fault.status.value:<9} "
                      f"counter {fault.debounce_counter:+d}")
            _announce(out, announced)
        result = ledger.clear(CODE, actor="demo:operator", reason="motor replaced",
                              at=t0 + timedelta(seconds=len(steps)))
        out.print(Text(printable(f"  clear -> {result.message}")))
        _announce(out, announced)
        out.print()
        out.print(render.history_table(
            [r for r in ledger.history(code=CODE) if r.seq > start]))
        out.print(render.transitions_table(
            [t for t in ledger.transitions(CODE) if t.seq > start]))
        check = ledger.verify()
        out.print(f"\nverify: {'OK' if check.ok else 'FAILED'} ({check.records} records, "
                  f"head hash {check.head_hash[:16]}...)")
    out.print("Try: faultledger list --all | faultledger history --code "
              f"{CODE} | faultledger verify")


def _announce(out: Console, announced: list[Notification]) -> None:
    for n in announced:
        out.print(f"      [magenta]~/events: {n.event_type.value}[/] "
                  f"(status {n.fault.status.value})")
    announced.clear()
