"""Turning faults and log records into terminal tables, JSON and CSV."""

from __future__ import annotations

from collections.abc import Iterable
from datetime import UTC, datetime
from typing import Any

from rich.console import Console
from rich.table import Table
from rich.text import Text

from faultledger.cli.safe_text import cell, printable
from faultledger.domain.clock import from_ns
from faultledger.domain.events import LogRecord
from faultledger.domain.fault import Fault
from faultledger.domain.integrity import canonical_json
from faultledger.domain.projector import Transition
from faultledger.domain.types import FaultStatus, Severity
from faultledger.store.database import describe

_STATUS_STYLE = {
    FaultStatus.CONFIRMED: "bold red",
    FaultStatus.PREFAILED: "yellow",
    FaultStatus.PREPASSED: "cyan",
    FaultStatus.HEALED: "green",
    FaultStatus.CLEARED: "dim",
}


def when(moment: datetime | None) -> str:
    return "-" if moment is None else moment.isoformat(timespec="milliseconds")


def short(moment: datetime | None) -> str:
    """Compact UTC time for table cells (the column header says UTC)."""
    if moment is None:
        return "-"
    return moment.astimezone(UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]


def severity_name(value: int) -> str:
    return Severity(value).name if value in Severity._value2member_map_ else str(value)


def fault_dict(fault: Fault) -> dict[str, Any]:
    return {
        "fault_code": fault.fault_code,
        "status": fault.status.value,
        "severity": fault.severity,
        "description": fault.description,
        "first_occurred": when(fault.first_occurred),
        "last_occurred": when(fault.last_occurred),
        "last_passed": None if fault.last_passed is None else when(fault.last_passed),
        "occurrence_count": fault.occurrence_count,
        "reporting_sources": list(fault.reporting_sources),
        "debounce_counter": fault.debounce_counter,
    }




def faults_table(faults: Iterable[Fault], title: str) -> Table:
    """Every value from outside (code, sources, description, title) is shown literally:
    ``safe_text.cell``, never markup, never a control character."""
    table = Table(title=cell(title), title_justify="left")
    for column in ("code", "status", "severity", "count", "counter", "last occurred (UTC)",
                   "sources", "description"):
        table.add_column(column, overflow="fold")
    for f in faults:
        table.add_row(
            cell(f.fault_code), cell(f.status.value, _STATUS_STYLE[f.status]),
            severity_name(f.severity), str(f.occurrence_count), str(f.debounce_counter),
            short(f.last_occurred), cell(", ".join(f.reporting_sources)), cell(f.description),
        )
    return table


def summary(record: LogRecord) -> str:
    p = record.payload
    if record.kind == "fault_reported":
        if p["event_type"] == "PASSED":
            return "PASSED"
        text = f"FAILED {severity_name(p['severity'])}"
        return text + (f" {p['description']!r}" if p["description"] else "")
    if record.kind == "fault_cleared":
        return f"cleared by {p['actor']}" + (f": {p['reason']}" if p["reason"] else "")
    if record.kind == "policy_changed":
        return canonical_json(p["policy"])
    if record.kind == "fault_confirmed_by_timer":
        return f"PREFAILED for {p['after_sec']} s"
    if record.kind == "goal_outcome":
        return f"goal {p['goal_id']} of {p['action']}: {p['status']}"
    return str(p.get("reason", ""))


def history_table(records: Iterable[LogRecord]) -> Table:
    table = Table(title="fault log", title_justify="left")
    for column in ("seq", "occurred (UTC)", "kind", "code", "source", "details"):
        table.add_column(column, overflow="fold")
    for r in records:
        table.add_row(str(r.seq), short(r.occurred_at), cell(r.kind), cell(r.fault_code or ""),
                      cell(r.source_id or ""), cell(summary(r)))
    return table


def transitions_table(items: Iterable[Transition]) -> Table:
    table = Table(title="status transitions", title_justify="left")
    for column in ("seq", "at (UTC)", "from", "to", "cause", "by"):
        table.add_column(column)
    for t in items:
        table.add_row(str(t.seq), short(from_ns(t.at_ns)),
                      t.from_status.value if t.from_status else "(new)", t.to_status.value,
                      cell(t.cause), cell(t.source_id))
    return table






def describe_url(url: str) -> str:
    return describe(url)


def complain(label: str, message: str) -> None:
    """One line on stderr: the label in red, the operator's text verbatim (never as markup,
    never wrapped, so brackets survive and the line stays greppable; control characters it
    quotes are shown escaped, see ``safe_text.printable``)."""
    Console(stderr=True, highlight=False, soft_wrap=True).print(
        Text.assemble((printable(label), "bold red"), " ", printable(message)))


def console(stderr: bool = False) -> Console:
    """Rich console; when piped (no terminal) tables get 200 columns instead of wrapping at 80."""
    probe = Console(stderr=stderr)
    width = None if probe.is_terminal else 200
    return Console(stderr=stderr, highlight=False, soft_wrap=False, width=width)
