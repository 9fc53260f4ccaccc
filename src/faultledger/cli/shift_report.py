"""``faultledger report-shift`` in the terminal: the report (reports/shift.py) as rich tables
that fit the terminal's width, times in the calendar's zone."""

from __future__ import annotations

from datetime import datetime

from rich.console import Group, RenderableType
from rich.text import Text

from faultledger.cli.render import (
    Column,
    Entry,
    Short,
    ambiguous,
    fitted,
    shorten,
    wrap,
)
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
    lines: list[RenderableType] = [head, _text(f"{report.span_text}, {report.length_text}",
                                               width)]
    if report.in_progress:
        lines.append(_text(f"in progress: figures up to {local_time(report, report.as_of)} "
                           f"{report.timezone}", width, "yellow"))
    compared = report.previous.id if report.previous else f"no previous {report.shift.name} shift"
    lines.append(cell(f"compared with {compared}", "dim"))
    lines.append(_text(report.headline, width, "bold"))
    notes = [_text(f"note: {note}", width, "yellow") for note in report.notes]
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


def _text(text: str, width: int | None, style: str = "") -> Text:
    """A line of the report, wrapped never inside a time (``render.wrap``)."""
    return Text("\n".join(wrap(printable(text), width)), style=style)


def _figures_table(report: ShiftReport, width: int | None = None) -> RenderableType:
    previous = report.previous.id if report.previous else "previous"
    columns = (Column("figure", cap=12), Column(report.shift.id, justify="right",
                                                no_wrap=True),
               Column(previous, drop=1, justify="right", no_wrap=True),
               Column("change", drop=2, justify="right", no_wrap=True),
               Column("change %", drop=3, justify="right", no_wrap=True))
    rows: list[list[Entry]] = [
        [item.label, value_text(item.kind, item.value), value_text(item.kind, item.previous),
         change_text(item), percent_text(item)] for item in report.figures]
    return fitted("key figures", columns, rows, width)


def _offenders_table(report: ShiftReport, width: int | None = None) -> RenderableType:
    columns = (Column("#", justify="right", no_wrap=True),
               Column("code", no_wrap=True, squeeze=3),
               Column("e-stops", justify="right", no_wrap=True, drop=1),
               Column("activations", justify="right", no_wrap=True),
               Column("confirmations", drop=2, justify="right", no_wrap=True),
               Column("failed reports", drop=4, justify="right", cap=8),
               Column("active time", drop=5, justify="right", cap=8),
               Column("MTTR", drop=6, justify="right", no_wrap=True))
    rows: list[list[Entry]] = [
        [str(rank), _id(group_text(row, "code")), str(row.estops), str(row.activations),
         str(row.confirmations), str(row.failed_reports), duration(row.active_seconds),
         duration(row.mttr_seconds)] for rank, row in enumerate(report.offenders, 1)]
    if not report.offenders:
        rows.append(["", "(no failed reports)", "", "", "", "", "", ""])
    return fitted(f"top {TOP} offenders (by activations, then confirmations)", columns, rows,
                  width)


def _id(text: str) -> Short:
    """A code or source: whole, or shortened (``HW_LEFT_ARM…ERGENCY_STOP``) when narrow."""
    return Short(cell(text), cell(shorten(text)))


def _when(report: ShiftReport, moment: datetime | None) -> Entry:
    """A downtime's start or end in the calendar's zone: the date and time; narrow, the clock
    time alone when it lies within the shift (which names the day)."""
    if moment is None:
        return "still CONFIRMED"
    local = report.local(moment)
    mark = f" {local:%Z}" if ambiguous(local) else ""
    full = f"{local:%Y-%m-%d %H:%M:%S}{mark}"
    within = report.shift.start <= moment <= report.shift.end
    return Short(full, f"{local:%H:%M:%S}{mark}" if within else f"{local:%Y-%m-%d %H:%M}{mark}")


def _downtimes_table(report: ShiftReport, width: int | None = None) -> RenderableType:
    # Narrower first: the source (shortened, then left out), the times (clock time only),
    # the whole episode, the code (shortened), the severity, then the end and the start.
    columns = (Column("code", no_wrap=True, squeeze=5),
               Column("source", drop=8, no_wrap=True, squeeze=9),
               Column("severity", drop=4, no_wrap=True),
               Column(f"confirmed at\n({report.timezone})", drop=2, no_wrap=True, squeeze=7),
               Column(f"ended\n({report.timezone})", drop=3, no_wrap=True, squeeze=7),
               Column("in shift", justify="right", no_wrap=True),
               Column("episode", drop=6, justify="right", no_wrap=True))
    rows: list[list[Entry]] = [
        [_id(d.fault_code), _id(d.source_id), severity_name(d.severity),
         _when(report, d.start), _when(report, d.end),
         duration(d.seconds_in_range), duration(d.seconds)] for d in report.downtimes]
    if not report.downtimes:
        rows.append(["(none)", "", "", "", "", "", ""])
    return fitted(cell(f"longest downtimes (CONFIRMED episodes, {report.timezone})"), columns,
                  rows, width)


def _hours_table(report: ShiftReport, width: int | None = None) -> RenderableType:
    # Bars as long as three of them fit beside the counts (at most 20, at least 6); the bars
    # that still do not fit go first, the e-stops' last.
    bar = 20 if width is None else min(20, max(6, (width - 65) // 3 - 3))
    columns = (Column("hour", no_wrap=True),
               Column("e-stops", justify="right", no_wrap=True),
               Column("", drop=2, no_wrap=True),
               Column("aborted goals", justify="right", no_wrap=True),
               Column("", drop=3, no_wrap=True),
               Column("activations", justify="right", no_wrap=True),
               Column("", drop=4, no_wrap=True),
               Column("confirmations", justify="right", no_wrap=True, drop=1))
    peak = max([1, *(max(h.estops, h.aborted_goals, h.activations) for h in report.hours)])
    rows: list[list[Entry]] = [
        [cell(hour.label), str(hour.estops),
         _bar(hour.estops, peak, "red", bar), str(hour.aborted_goals),
         _bar(hour.aborted_goals, peak, "blue", bar), str(hour.activations),
         _bar(hour.activations, peak, "yellow", bar), str(hour.confirmations)]
        for hour in report.hours]
    return fitted(cell(f"per hour ({report.timezone})"), columns, rows, width)


def _bar(value: int, peak: int, style: str, width: int = 20) -> Text:
    return Text("█" * round(value / peak * width), style=style)
