"""Turning faults and log records into terminal tables, JSON and CSV."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any, Literal

from rich.cells import cell_len
from rich.console import Console
from rich.table import Table
from rich.text import Text

from faultledger.cli.safe_text import cell, printable
from faultledger.domain.clock import from_ns
from faultledger.domain.events import LogRecord
from faultledger.domain.fault import Fault
from faultledger.domain.integrity import canonical_json
from faultledger.domain.projector import Transition
from faultledger.domain.types import FaultStatus, severity_name
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




@dataclass(frozen=True, slots=True)
class Column:
    """A table column that may be left out when the terminal is too narrow.

    ``drop``: 0 = always shown; otherwise the column with the highest ``drop`` is left out
    first. ``no_wrap`` cells (codes, statuses, ids) are never split; the others fold, at
    spaces first, down to ``cap`` characters.
    """

    header: str
    drop: int = 0
    no_wrap: bool = False
    justify: Literal["left", "right", "center"] = "left"
    cap: int = 14


Cell = Text | str
_BORDERS = 1
"""Characters of a table's outer border on one side; each column adds padding and a rule."""


def _plain(value: Cell) -> str:
    return value.plain if isinstance(value, Text) else value


def _floor(column: Column, cells: Iterable[Cell]) -> int:
    """The narrowest this column can be without splitting what must not be split."""
    texts = [column.header, *(_plain(c) for c in cells)]
    if column.no_wrap:
        return max(cell_len(line) for t in texts for line in t.splitlines() or [""])
    words = [cell_len(w) for t in texts for w in t.split()] or [1]
    return min(max(words), column.cap)


def table_width(widths: Iterable[int]) -> int:
    """The width of a default-box table whose columns have these content widths."""
    items = list(widths)
    return sum(items) + 3 * len(items) + _BORDERS


def fitted(title: Cell, columns: Sequence[Column], rows: Sequence[Sequence[Cell]],
           width: int | None) -> Table:
    """A table of the columns that fit in ``width`` (None: every column, ``--wide``),
    leaving out the droppable ones, highest ``drop`` first, until it fits."""
    floors = [_floor(c, (row[i] for row in rows)) for i, c in enumerate(columns)]
    keep = list(range(len(columns)))
    if width is not None:
        order = sorted((i for i, c in enumerate(columns) if c.drop),
                       key=lambda i: -columns[i].drop)
        for index in order:
            if table_width(floors[i] for i in keep) <= width:
                break
            keep.remove(index)
    table = Table(title=title, title_justify="left")
    for i in keep:
        c = columns[i]
        table.add_column(c.header, justify=c.justify, no_wrap=c.no_wrap,
                         overflow="ellipsis" if c.no_wrap else "fold",
                         min_width=floors[i] if c.no_wrap else None)
    for row in rows:
        table.add_row(*(row[i] for i in keep))
    return table


def faults_table(faults: Iterable[Fault], title: str, width: int | None = None) -> Table:
    """Every value from outside (code, sources, description, title) is shown literally:
    ``safe_text.cell``, never markup, never a control character. Columns that do not fit in
    ``width`` go first: sources, description, counter, count, last occurred, severity."""
    columns = (Column("code", no_wrap=True), Column("status", no_wrap=True),
               Column("severity", drop=1, no_wrap=True),
               Column("count", drop=3, justify="right"),
               Column("counter", drop=4, justify="right"),
               Column("last occurred (UTC)", drop=2, no_wrap=True),
               Column("sources", drop=6), Column("description", drop=5))
    rows: list[list[Cell]] = [
        [cell(f.fault_code), cell(f.status.value, _STATUS_STYLE[f.status]),
         severity_name(f.severity), str(f.occurrence_count), str(f.debounce_counter),
         short(f.last_occurred), cell(", ".join(f.reporting_sources)), cell(f.description)]
        for f in faults]
    return fitted(cell(title), columns, rows, width)


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


def history_table(records: Iterable[LogRecord], width: int | None = None) -> Table:
    """Columns that do not fit in ``width`` go first: source, kind, occurred."""
    columns = (Column("seq", no_wrap=True, justify="right"),
               Column("occurred (UTC)", drop=2, no_wrap=True),
               Column("kind", drop=3), Column("code", no_wrap=True),
               Column("source", drop=4), Column("details", drop=1, cap=16))
    rows: list[list[Cell]] = [
        [str(r.seq), short(r.occurred_at), cell(r.kind), cell(r.fault_code or ""),
         cell(r.source_id or ""), cell(summary(r))] for r in records]
    return fitted("fault log", columns, rows, width)


def transitions_table(items: Iterable[Transition], width: int | None = None,
                      reasons: dict[int, str] | None = None) -> Table:
    """Columns that do not fit in ``width`` go first: cause, at. ``reasons``: the clear
    reason of a seq, shown after its cause."""
    why = reasons or {}
    columns = (Column("seq", no_wrap=True, justify="right"),
               Column("at (UTC)", drop=2, no_wrap=True),
               Column("from", no_wrap=True), Column("to", no_wrap=True),
               Column("cause", drop=3), Column("by", drop=1))
    rows: list[list[Cell]] = [
        [str(t.seq), short(from_ns(t.at_ns)),
         t.from_status.value if t.from_status else "(new)", t.to_status.value,
         cell(f"{t.cause}: {why[t.seq]}" if why.get(t.seq) else t.cause), cell(t.source_id)]
        for t in items]
    return fitted("status transitions", columns, rows, width)


def describe_url(url: str) -> str:
    return describe(url)


def complain(label: str, message: str) -> None:
    """One line on stderr: the label in red, the operator's text verbatim (never as markup,
    never wrapped, so brackets survive and the line stays greppable; control characters it
    quotes are shown escaped, see ``safe_text.printable``)."""
    Console(stderr=True, highlight=False, soft_wrap=True).print(
        Text.assemble((printable(label), "bold red"), " ", printable(message)))


def console(stderr: bool = False, *, wide: bool = False) -> Console:
    """Rich console; when piped (no terminal) tables get 200 columns instead of wrapping at 80.
    ``wide``: as wide as the widest table (``--wide``: every column, the terminal wraps)."""
    probe = Console(stderr=stderr)
    width = None if probe.is_terminal else 200
    if wide:
        width = max(probe.width, WIDE)
    return Console(stderr=stderr, highlight=False, soft_wrap=False, width=width)


def say(text: str) -> None:
    """One line of text on stdout, shown literally: wrapped at word boundaries to a terminal's
    width, a single unwrapped line when piped (scripts read it whole)."""
    out = console()
    if out.is_terminal:
        out.print(cell(text))
    else:
        print(printable(text), flush=True)


WIDE = 1000
"""The console width of ``--wide``: no table is cut to fit."""


def fit_width(out: Console, wide: bool) -> int | None:
    """The width tables are fitted to on ``out``: None (every column) with ``--wide``."""
    return None if wide else out.width
