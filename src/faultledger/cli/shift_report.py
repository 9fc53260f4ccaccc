"""``faultledger report-shift`` in the terminal: the report (reports/shift.py) as rich tables
that fit the terminal's width."""

from __future__ import annotations

from rich.console import Group, RenderableType
from rich.table import Table
from rich.text import Text

from faultledger.cli.render import Cell, Column, fitted
from faultledger.cli.safe_text import cell, printable
from faultledger.domain.types import severity_name
from faultledger.reports.shift import (
    GLOSSARY,
    TOP,
    ShiftReport,
    change_text,
    duration,
    group_text,
    local_time,
    percent_text,
    value_text,
)


def terminal(report: ShiftReport, width: int | None = None, *,
             glossary: bool = False) -> RenderableType:
    """The report as rich renderables, for ``faultledger report-shift``; every table fits in
    ``width`` (None: every column, ``--wide``)."""
    shift = report.shift
    head = Text.assemble(("Shift report ", "bold"), (printable(shift.id), "bold cyan"))
    lines = [head, cell(f"{report.span_text}, {report.length_text}")]
    if report.in_progress:
        lines.append(cell(f"in progress: figures up to {local_time(report, report.as_of)}",
                          "yellow"))
    compared = report.previous.id if report.previous else f"no previous {report.shift.name} shift"
    lines.append(cell(f"compared with {compared}", "dim"))
    lines.append(cell(report.headline, "bold"))
    notes = [cell(f"note: {note}", "yellow") for note in report.notes]
    parts: list[RenderableType] = [*lines, _figures_table(report, width), *notes,
                                   _offenders_table(report, width),
                                   _downtimes_table(report, width),
                                   _hours_table(report, width)]
    if glossary:
        parts.append(Text("glossary", style="bold"))
        parts.extend(Text.assemble((f"{term}: ", "bold"), meaning)
                     for term, meaning in GLOSSARY)
    else:
        parts.append(cell("what the figures mean: faultledger report-shift --glossary "
                          "(or docs/statistics.md)", "dim"))
    return Group(*parts)


def _figures_table(report: ShiftReport, width: int | None = None) -> Table:
    previous = report.previous.id if report.previous else "previous"
    columns = (Column("figure", cap=12), Column(report.shift.id, justify="right",
                                                no_wrap=True),
               Column(previous, drop=1, justify="right", no_wrap=True),
               Column("change", drop=2, justify="right", no_wrap=True),
               Column("change %", drop=3, justify="right", no_wrap=True))
    rows: list[list[Cell]] = [
        [item.label, value_text(item.kind, item.value), value_text(item.kind, item.previous),
         change_text(item), percent_text(item)] for item in report.figures]
    return fitted("key figures", columns, rows, width)


def _offenders_table(report: ShiftReport, width: int | None = None) -> Table:
    columns = (Column("#", justify="right", no_wrap=True), Column("code", no_wrap=True),
               Column("activations", justify="right", no_wrap=True),
               Column("confirmations", drop=2, justify="right", no_wrap=True),
               Column("failed reports", drop=3, justify="right", cap=8),
               Column("active time", drop=4, justify="right", cap=8),
               Column("MTTR", drop=5, justify="right", no_wrap=True))
    rows: list[list[Cell]] = [
        [str(rank), cell(group_text(row, "code")), str(row.activations),
         str(row.confirmations), str(row.failed_reports), duration(row.active_seconds),
         duration(row.mttr_seconds)] for rank, row in enumerate(report.offenders, 1)]
    if not report.offenders:
        rows.append(["", "(no failed reports)", "", "", "", "", ""])
    return fitted(f"top {TOP} offenders (by activations, then confirmations)", columns, rows,
                  width)


def _downtimes_table(report: ShiftReport, width: int | None = None) -> Table:
    columns = (Column("code", no_wrap=True), Column("source", drop=5),
               Column("severity", drop=4, no_wrap=True), Column("confirmed at", drop=2, cap=10),
               Column("ended", drop=3, cap=10), Column("in shift", justify="right", no_wrap=True),
               Column("episode", drop=1, justify="right", no_wrap=True))
    rows: list[list[Cell]] = [
        [cell(d.fault_code), cell(d.source_id), severity_name(d.severity),
         local_time(report, d.start), local_time(report, d.end),
         duration(d.seconds_in_range), duration(d.seconds)] for d in report.downtimes]
    if not report.downtimes:
        rows.append(["(none)", "", "", "", "", "", ""])
    return fitted(cell(f"longest downtimes (CONFIRMED episodes, {report.timezone})"), columns,
                  rows, width)


def _hours_table(report: ShiftReport, width: int | None = None) -> Table:
    bar = 20 if width is None or width >= 110 else 6
    columns = (Column("hour", no_wrap=True),
               Column("activations", justify="right", no_wrap=True), Column("", drop=3),
               Column("confirmations", justify="right", no_wrap=True), Column("", drop=2),
               Column("aborted goals", justify="right", no_wrap=True), Column("", drop=1))
    peak = max([1, *(max(h.activations, h.confirmations, h.aborted_goals)
                     for h in report.hours)])
    rows: list[list[Cell]] = [
        [cell(hour.label), str(hour.activations), _bar(hour.activations, peak, "red", bar),
         str(hour.confirmations), _bar(hour.confirmations, peak, "yellow", bar),
         str(hour.aborted_goals), _bar(hour.aborted_goals, peak, "blue", bar)]
        for hour in report.hours]
    return fitted(cell(f"per hour ({report.timezone})"), columns, rows, width)


def _bar(value: int, peak: int, style: str, width: int = 20) -> Text:
    return Text("█" * round(value / peak * width), style=style)
