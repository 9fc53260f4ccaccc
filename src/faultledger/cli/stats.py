"""`faultledger stats` and `faultledger report-shift`: statistics for people and spreadsheets.

The commands translate options into ``FaultLedger.stats`` / ``downtimes`` calls and render the
rows; every figure is defined in docs/statistics.md and computed by the service.
"""

from __future__ import annotations

import csv
import io
import json
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import fields
from datetime import datetime
from pathlib import Path
from typing import Annotated, NoReturn

import typer
from rich.table import Table

from faultledger.cli import render
from faultledger.cli.safe_text import cell, printable
from faultledger.cli.shift_report import build_report, duration, group_text, terminal
from faultledger.domain.periods import PERIOD_KINDS, default_calendar, parse_bound
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import GROUP_KEYS, StatsRow
from faultledger.errors import FaultLedgerError
from faultledger.service.config import load_settings, load_shift_calendar
from faultledger.service.ledger import FaultLedger
from faultledger.service.output_files import OutputFileError, check_target, write_output

# The same options as cli/main.py's (kept here: main imports this module, not the reverse).
DbOption = Annotated[
    str | None,
    typer.Option("--db", envvar="FAULTLEDGER_DB", show_envvar=True,
                 help="Database URL (default: the config's, else sqlite:///var/faultledger.db)."),
]
ConfigOption = Annotated[
    Path | None,
    typer.Option("--config", envvar="FAULTLEDGER_CONFIG", show_envvar=True,
                 help="YAML configuration file (see config/faultledger.yaml)."),
]
ShiftsOption = Annotated[
    Path | None,
    typer.Option("--shifts", help="Shift calendar YAML (see config/shifts.yaml). Default: the "
                 "config's `shifts`, else UTC morning/afternoon/night from 06:00."),
]
AsOfOption = Annotated[
    str | None,
    typer.Option("--as-of", help="End CONFIRMED episodes still open at this time (default: "
                 "now); a date, date-time (local to the calendar) or shift id."),
]
_FIGURES = [f.name for f in fields(StatsRow) if f.name not in ("period", "group")]
_PERIOD_FIELDS = ["period", "period_name", "production_day", "start", "end"]


def register(app: typer.Typer) -> None:
    """Add `stats` and `report-shift` to the `faultledger` app."""
    app.command("stats")(stats)
    app.command("report-shift")(report_shift)


def fail(message: str, code: int = 2) -> NoReturn:
    """One line on stderr and a non-zero exit, like the other commands' errors."""
    render.complain("error:", message)
    raise typer.Exit(code)


@contextmanager
def reading(db: str | None, config: Path | None, shifts: Path | None
            ) -> Iterator[tuple[FaultLedger, ShiftCalendar]]:
    """A read-only ledger (never creates, migrates or records, like `list`/`history`) and the
    calendar: ``--shifts``, else the config's ``shifts``, else the built-in default. Service
    errors become one-line messages with exit code 2."""
    try:
        settings = load_settings(config)
        path = shifts or settings.shifts
        calendar = default_calendar() if path is None else load_shift_calendar(path)
        ledger = FaultLedger.open(db or settings.database.url, create=False, upgrade=False,
                                  max_batch=settings.database.max_batch, background=False,
                                  calendar=calendar)
    except FaultLedgerError as error:
        fail(str(error))
    try:
        yield ledger, calendar
    except FaultLedgerError as error:
        fail(str(error))
    finally:
        ledger.close()


def _as_of(text: str | None, calendar: ShiftCalendar) -> datetime | None:
    if text is None:
        return None
    try:
        return parse_bound(text, calendar, upper=False)
    except ValueError as error:
        fail(f"--as-of: {error}")


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
        "--since", help="Start (inclusive): 2026-11-21, 2026-11-21T06:00 (calendar-local "
        "unless it has an offset) or a shift id (its start). Default: until - 24 h.")] = None,
    until: Annotated[str | None, typer.Option(
        "--until", help="End (exclusive): like --since; a shift id means its end. "
        "Default: --as-of, else now (what happened a second ago is counted).")] = None,
    as_of: AsOfOption = None,
    as_json: Annotated[bool, typer.Option("--json", help="JSON array of every figure.")
                       ] = False,
    as_csv: Annotated[bool, typer.Option("--csv", help="CSV of every figure, header row.")
                      ] = False,
    shifts: ShiftsOption = None,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """Fault statistics per shift, day, hour or 10 minutes (docs/statistics.md)."""
    if as_json and as_csv:
        fail("choose one of --json and --csv")
    groups = group_by or []
    with reading(db, config, shifts) as (ledger, calendar):
        rows = ledger.stats(by, since, until, code, groups, calendar=calendar,
                            as_of=_as_of(as_of, calendar))
    if as_json:
        typer.echo(json.dumps([row.as_dict() for row in rows], indent=2))
    elif as_csv:
        sys.stdout.write(stats_csv(rows, groups))
    else:
        render.console().print(stats_table(rows, by, groups, calendar, code))


def stats_csv(rows: Sequence[StatsRow], group_by: Sequence[str]) -> str:
    """Every field of ``StatsRow.as_dict``; empty cells for undefined figures."""
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=[*_PERIOD_FIELDS, *group_by, *_FIGURES],
                            lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow(row.as_dict())
    return out.getvalue()


def stats_table(rows: Sequence[StatsRow], by: str, group_by: Sequence[str],
                calendar: ShiftCalendar, codes: Sequence[str] | None) -> Table:
    """The figures people read first; --json/--csv have all of them. Rows grouped by action
    hold goal figures only (docs/statistics.md): they show the three goal counts."""
    zone = calendar.zone
    title = f"statistics by {by}"
    if rows:
        first, last = rows[0].period.start, rows[-1].period.end
        title += (f", {first.astimezone(zone):%Y-%m-%d %H:%M} – "
                  f"{last.astimezone(zone):%Y-%m-%d %H:%M} {calendar.timezone}")
    if codes:
        title += f", codes {' '.join(codes)}"
    table = Table(title=cell(title), title_justify="left")
    table.add_column("period", overflow="fold")
    table.add_column("local time", overflow="fold")
    for key in group_by:
        table.add_column(cell(key), overflow="fold")
    goals_only = "action" in group_by
    columns = (("aborted goals", "canceled goals", "succeeded goals") if goals_only else
               ("failed", "activations", "aborted goals", "confirmations", "heals", "clears",
                "active", "MTTR", "flood %", "chattering", "stale"))
    for column in columns:
        table.add_column(column, justify="right")
    for row in rows:
        start, end = row.period.start.astimezone(zone), row.period.end.astimezone(zone)
        span = (f"{start:%Y-%m-%d %H:%M}–{end:%H:%M}" if end.date() == start.date()
                else f"{start:%Y-%m-%d %H:%M}–{end:%Y-%m-%d %H:%M}")
        figures = ([str(row.aborted_goals), str(row.canceled_goals), str(row.succeeded_goals)]
                   if goals_only else
                   [str(row.failed_reports), str(row.activations), str(row.aborted_goals),
                    str(row.confirmations), str(row.heals), str(row.clears),
                    duration(row.active_seconds), duration(row.mttr_seconds),
                    f"{row.flood_percent:.1f}", str(row.chattering_codes),
                    str(row.stale_codes)])
        table.add_row(cell(row.period.id), span,
                      *(cell(group_text(row, key)) for key in group_by), *figures)
    if not rows:
        table.add_row("(no rows)", *[""] * (len(group_by) + len(columns) + 1))
    return table


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
    with reading(db, config, shifts) as (ledger, calendar):
        report = build_report(ledger, calendar, shift_id, _as_of(as_of, calendar))
    render.console().print(terminal(report))
    if html_file is None and png_file is None:
        return
    from faultledger.cli import shift_report_html  # matplotlib: only when a file is wanted

    outputs: list[tuple[Path, bytes]] = []
    if html_file is not None:
        outputs.append((html_file, shift_report_html.html(report).encode("utf-8")))
    if png_file is not None:
        outputs.append((png_file, shift_report_html.charts_png(report)))
    for path, data in outputs:
        try:
            write_output(path, data, force)
        except OutputFileError as error:
            fail(str(error))
        typer.echo(printable(f"wrote {path}"))
