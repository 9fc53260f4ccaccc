"""`faultledger stats` and `faultledger report-shift`: statistics for people and spreadsheets.

The commands translate options into ``FaultLedger.stats`` / ``downtimes`` calls and render the
rows; every figure is defined in docs/statistics.md and computed by the service.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from faultledger.cli import render
from faultledger.cli.options import (
    TIME_HELP,
    ConfigOption,
    DbOption,
    ShiftsOption,
    WideOption,
    fail,
    opened,
    parse_time,
    prepare,
)
from faultledger.cli.render import Cell, Column, fitted
from faultledger.cli.safe_text import cell, printable
from faultledger.cli.shift_report import terminal
from faultledger.domain.periods import PERIOD_KINDS
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import GROUP_KEYS, StatsRow
from faultledger.reports.shift import build_report, duration, group_text
from faultledger.service.exports import stats_csv
from faultledger.service.output_files import OutputFileError, check_target, write_output

AsOfOption = Annotated[
    str | None,
    typer.Option("--as-of", help=f"End CONFIRMED episodes still open at this time (default: "
                 f"now): {TIME_HELP}."),
]


def register(app: typer.Typer) -> None:
    """Add `stats` and `report-shift` to the `faultledger` app."""
    app.command("stats")(stats)
    app.command("report-shift")(report_shift)


def _as_of(text: str | None, calendar: ShiftCalendar) -> datetime | None:
    return parse_time(text, "--as-of", calendar)


# -- stats ---------------------------------------------------------------------------------------
def stats(
    by: Annotated[str, typer.Option(
        "--by", help=f"Period: {', '.join(PERIOD_KINDS)}.")] = "shift",
    code: Annotated[list[str] | None, typer.Option(
        "--code", help="Fault code glob, e.g. 'HW_*_EMERGENCY_STOP' (repeatable).")] = None,
    group_by: Annotated[list[str] | None, typer.Option(
        "--group-by", help=f"Group rows by {', '.join(GROUP_KEYS)} (repeatable; action: "
        "goal outcomes per action, with source only).")] = None,
    since: Annotated[str | None, typer.Option(
        "--since", help=f"Start (inclusive): {TIME_HELP}. Default: until - 24 h.")] = None,
    until: Annotated[str | None, typer.Option(
        "--until", help="End (exclusive): like --since; a shift id means its end. "
        "Default: --as-of, else now (what happened a second ago is counted).")] = None,
    as_of: AsOfOption = None,
    as_json: Annotated[bool, typer.Option("--json", help="JSON array of every figure.")
                       ] = False,
    as_csv: Annotated[bool, typer.Option("--csv", help="CSV of every figure, header row.")
                      ] = False,
    wide: WideOption = False,
    shifts: ShiftsOption = None,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """Fault statistics per shift, day, hour or 10 minutes (docs/statistics.md).

    Narrow terminals show the first columns only (--wide: all; --json/--csv: every figure).
    """
    if as_json and as_csv:
        fail("choose one of --json and --csv")
    groups = group_by or []
    setup = prepare(db, config, shifts=shifts)
    calendar = setup.calendar
    first = parse_time(since, "--since", calendar)
    last = parse_time(until, "--until", calendar, upper=True)
    moment = _as_of(as_of, calendar)
    with opened(setup) as ledger:
        rows = ledger.stats(by, first, last, code, groups, calendar=calendar, as_of=moment)
    if as_json:
        typer.echo(json.dumps([row.as_dict() for row in rows], indent=2))
    elif as_csv:
        sys.stdout.write(stats_csv(rows, groups))
    else:
        out = render.console(wide=wide)
        out.print(stats_table(rows, by, groups, calendar, code, render.fit_width(out, wide)))


def stats_table(rows: Sequence[StatsRow], by: str, group_by: Sequence[str],
                calendar: ShiftCalendar, codes: Sequence[str] | None,
                width: int | None = None) -> Table:
    """The figures people read first; --json/--csv have all of them. Rows grouped by action
    hold goal figures only (docs/statistics.md): they show the three goal counts. Columns that
    do not fit in ``width`` go from the right (the least read first)."""
    zone = calendar.zone
    title = f"statistics by {by}"
    if rows:
        first, last = rows[0].period.start, rows[-1].period.end
        title += (f", {first.astimezone(zone):%Y-%m-%d %H:%M} – "
                  f"{last.astimezone(zone):%Y-%m-%d %H:%M} {calendar.timezone}")
    if codes:
        title += f", codes {' '.join(codes)}"
    goals_only = "action" in group_by
    figures = (("aborted goals", "canceled goals", "succeeded goals") if goals_only else
               ("failed", "activations", "aborted goals", "confirmations", "heals", "clears",
                "active", "MTTR", "flood %", "chattering", "stale"))
    # Dropped first: the last figure; then the others right to left, the local time before
    # the first two figures; the period and the group keys stay.
    ranks = {name: i + 2 for i, name in enumerate(figures)}
    ranks[figures[0]], ranks[figures[1]] = 2, 1
    columns = [Column("period", no_wrap=True), Column("local time", drop=3, cap=16),
               *(Column(key, no_wrap=True) for key in group_by),
               *(Column(name, drop=ranks[name], justify="right", no_wrap=True)
                 for name in figures)]
    table_rows: list[list[Cell]] = []
    for row in rows:
        start, end = row.period.start.astimezone(zone), row.period.end.astimezone(zone)
        span = (f"{start:%Y-%m-%d %H:%M}–{end:%H:%M}" if end.date() == start.date()
                else f"{start:%Y-%m-%d %H:%M}–{end:%Y-%m-%d %H:%M}")
        values = ([str(row.aborted_goals), str(row.canceled_goals), str(row.succeeded_goals)]
                  if goals_only else
                  [str(row.failed_reports), str(row.activations), str(row.aborted_goals),
                   str(row.confirmations), str(row.heals), str(row.clears),
                   duration(row.active_seconds), duration(row.mttr_seconds),
                   f"{row.flood_percent:.1f}", str(row.chattering_codes),
                   str(row.stale_codes)])
        table_rows.append([cell(row.period.id), span,
                           *(cell(group_text(row, key)) for key in group_by), *values])
    if not rows:
        table_rows.append(["(no rows)", *[""] * (len(columns) - 1)])
    return fitted(cell(title), columns, table_rows, width)


# -- report-shift --------------------------------------------------------------------------------
def report_shift(
    shift_id: Annotated[str | None, typer.Argument(
        help="Shift instance, e.g. 2026-11-21/night. Default: the last completed shift.",
        show_default=False)] = None,
    html_file: Annotated[Path | None, typer.Option(
        "--html", help="Also write the report as one self-contained HTML file.")] = None,
    png_file: Annotated[Path | None, typer.Option(
        "--png", help="Also write the charts (per hour, top offenders) as a PNG.")] = None,
    force: Annotated[bool, typer.Option(
        "--force", help="Replace existing --html/--png files (default: refuse).")] = False,
    as_of: AsOfOption = None,
    glossary: Annotated[bool, typer.Option(
        "--glossary", help="Also explain every figure (activations, flood, MTTR…).")] = False,
    wide: WideOption = False,
    shifts: ShiftsOption = None,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """End-of-shift summary: key figures against the previous instance of the same shift,
    top offenders, longest downtimes and activity per hour."""
    for target in (html_file, png_file):
        if target is not None:
            try:
                check_target(target, force)  # refuse before any work, write nothing
            except OutputFileError as error:
                fail(str(error))
    setup = prepare(db, config, shifts=shifts)
    moment = _as_of(as_of, setup.calendar)
    with opened(setup) as ledger:
        report = build_report(ledger, setup.calendar, shift_id, moment)
    out = render.console(wide=wide)
    out.print(terminal(report, render.fit_width(out, wide), glossary=glossary))
    if html_file is None and png_file is None:
        return
    from faultledger.reports import shift_html  # matplotlib: only when a file is wanted

    outputs: list[tuple[Path, bytes]] = []
    if html_file is not None:
        outputs.append((html_file, shift_html.html(report).encode("utf-8")))
    if png_file is not None:
        outputs.append((png_file, shift_html.charts_png(report)))
    for path, data in outputs:
        try:
            write_output(path, data, force)
        except OutputFileError as error:
            fail(str(error))
        typer.echo(printable(f"wrote {path}"))
