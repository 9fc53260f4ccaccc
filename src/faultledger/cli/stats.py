"""`faultledger stats` and `faultledger report-shift`: statistics for people and spreadsheets.

The commands translate options into ``FaultLedger.stats`` / ``downtimes`` calls and render the
rows; every figure is defined in docs/statistics.md and computed by the service.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from datetime import datetime, timedelta
from pathlib import Path
from typing import Annotated

import typer
from rich.console import RenderableType

from faultledger.cli import render
from faultledger.cli.options import (
    TIME_HELP,
    ConfigOption,
    DbOption,
    RobotOption,
    ShiftsOption,
    WideOption,
    fail,
    opened,
    parse_time,
    prepare,
    settings_for,
)
from faultledger.cli.render import Column, Entry, Short, fitted
from faultledger.cli.safe_text import cell, printable
from faultledger.cli.shift_report import terminal
from faultledger.domain.fleet_stats import FLEET_KEYS
from faultledger.domain.periods import PERIOD_KINDS
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import GROUP_KEYS, StatsRow
from faultledger.reports.shift import build_report, duration, group_text
from faultledger.service.exports import stats_csv
from faultledger.service.fleet import Fleet
from faultledger.service.output_files import OutputFileError, check_target, write_output

AsOfOption = Annotated[
    str | None,
    typer.Option("--as-of", metavar="TIME",
                 help=f"End CONFIRMED episodes still open at this time (default: "
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
        "--by", metavar="PERIOD", help=f"Period: {', '.join(PERIOD_KINDS)}.")] = "shift",
    code: Annotated[list[str] | None, typer.Option(
        "--code", metavar="GLOB",
        help="Fault code glob, e.g. 'HW_*_EMERGENCY_STOP' (repeatable).")] = None,
    group_by: Annotated[list[str] | None, typer.Option(
        "--group-by", metavar="KEY",
        help=f"Group rows by {', '.join(GROUP_KEYS)} (repeatable; action: "
        "goal outcomes per action, with source only); on a fleet central also by "
        f"{', '.join(FLEET_KEYS)} (the robots' logs; line and site from the config's "
        "fleet.robots).")] = None,
    robot: RobotOption = None,
    since: Annotated[str | None, typer.Option(
        "--since", metavar="TIME",
        help=f"Start (inclusive): {TIME_HELP}. Default: 24 hours before --until.")] = None,
    until: Annotated[str | None, typer.Option(
        "--until", metavar="TIME", help="End (exclusive): like --since; a shift id means its end. "
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
    """Fault statistics per shift, day, hour or 10 minutes.

    The figures are defined in docs/statistics.md. Narrow terminals show the first columns
    only (--wide: all; --json/--csv: every figure); times are in the calendar's zone.
    """
    if as_json and as_csv:
        fail("choose one of --json and --csv")
    groups = group_by or []
    setup = prepare(db, config, shifts=shifts)
    calendar = setup.calendar
    first = parse_time(since, "--since", calendar)
    last = parse_time(until, "--until", calendar, upper=True)
    moment = _as_of(as_of, calendar)
    fleet_wide = robot is not None or any(key in FLEET_KEYS for key in groups)
    with opened(setup) as ledger:
        if fleet_wide:
            settings = settings_for(config)
            with Fleet(ledger) as robot_logs:
                rows = robot_logs.stats(
                    by, first, last, code, groups, robot=robot, as_of=moment,
                    labels=settings.fleet.labels() if settings.fleet else None)
        else:
            rows = ledger.stats(by, first, last, code, groups, calendar=calendar,
                                as_of=moment)
    if as_json:
        typer.echo(json.dumps([row.as_dict() for row in rows], indent=2))
    elif as_csv:
        sys.stdout.write(stats_csv(rows, groups))
    else:
        out = render.console(wide=wide)
        out.print(stats_table(rows, by, groups, calendar, code, render.fit_width(out, wide)))
        if any(row.complete is False for row in rows):
            render.say(PROVISIONAL_NOTE)


PROVISIONAL = "*"
PROVISIONAL_NOTE = ("* provisional: a robot in the row has not pushed past the period's end "
                    "yet (still syncing: figures may grow)")


FIGURES = ("e-stops", "aborted goals", "activations", "failed", "confirmations", "heals",
           "clears", "active", "MTTR", "flood %", "chattering", "stale")
"""The figures of the table in the order of the shift report's key figures (e-stops and
aborted goals first); --json/--csv carry every figure."""
GOAL_FIGURES = ("aborted goals", "canceled goals", "succeeded goals")
"""Rows grouped by action hold goal figures only."""


def _figures(row: StatsRow) -> dict[str, str]:
    return {"e-stops": str(row.estops), "aborted goals": str(row.aborted_goals),
            "activations": str(row.activations), "failed": str(row.failed_reports),
            "confirmations": str(row.confirmations), "heals": str(row.heals),
            "clears": str(row.clears), "active": duration(row.active_seconds),
            "MTTR": duration(row.mttr_seconds), "flood %": f"{row.flood_percent:.1f}",
            "chattering": str(row.chattering_codes), "stale": str(row.stale_codes),
            "canceled goals": str(row.canceled_goals),
            "succeeded goals": str(row.succeeded_goals)}


def _group_cell(row: StatsRow, key: str) -> str:
    """A group key as shown; a robot with a replaced database has a row per log, told apart
    by the start of its ledger_id."""
    text = group_text(row, key)
    ledger_id = row.group.get("ledger_id")
    return f"{text} ({str(ledger_id)[:8]})" if key == "robot" and ledger_id else text


def local_span(row: StatsRow, calendar: ShiftCalendar) -> Short:
    """The period in the calendar's zone: ``2026-11-21 22:00–2026-11-22 06:00``; shorter,
    ``22:00–06:00``, when the period id already says the day (not for `unscheduled`)."""
    zone = calendar.zone
    start, end = row.period.start.astimezone(zone), row.period.end.astimezone(zone)
    marks = [render.ambiguous(start), render.ambiguous(end)]
    first = f"{start:%H:%M}" + (f" {start:%Z}" if marks[0] else "")
    last = f"{end:%H:%M}" + (f" {end:%Z}" if marks[1] else "")
    full = (f"{start:%Y-%m-%d} {first}–{last}" if end.date() == start.date()
            else f"{start:%Y-%m-%d} {first}–{end:%Y-%m-%d} {last}")
    if row.period.production_day is None:  # unscheduled: only the span says when
        return Short(full, full)
    if last == "00:00" and end.date() == start.date() + timedelta(days=1):
        last = "24:00"  # a day, or a shift ending at midnight: 00:00–24:00, 14:00–24:00
    return Short(full, f"{first}–{last}")


def stats_table(rows: Sequence[StatsRow], by: str, group_by: Sequence[str],
                calendar: ShiftCalendar, codes: Sequence[str] | None,
                width: int | None = None) -> RenderableType:
    """The figures people read first; --json/--csv have all of them. Rows grouped by action
    hold goal figures only (docs/statistics.md): they show the three goal counts. Columns that
    do not fit in ``width`` go from the right (the least read first), then the local time
    (shortened first); the period, the group keys, e-stops, aborted goals, activations and
    failed stay, as long as they fit."""
    zone = calendar.zone
    title = f"statistics by {by}"
    if rows:
        first, last = rows[0].period.start, rows[-1].period.end
        title += (f", {first.astimezone(zone):%Y-%m-%d %H:%M} – "
                  f"{last.astimezone(zone):%Y-%m-%d %H:%M} {calendar.timezone}")
    if codes:
        title += f", codes {' '.join(codes)}"
    goals_only = "action" in group_by
    # Rows grouped by fault keys only (code, source, severity) have no goal figures.
    fault_keys = [key for key in group_by if key not in FLEET_KEYS]
    figures = (GOAL_FIGURES if goals_only else FIGURES if not fault_keys
               else tuple(name for name in FIGURES if name != "aborted goals"))
    # Dropped first: the last figure, then the others right to left; then the local time
    # (shortened first), then long ids of the groups are shortened; the first four figures go
    # last, right to left (e-stops and aborted goals stay longest).
    ranks = {name: 20 + len(figures) - i for i, name in enumerate(figures)}
    for i, name in enumerate(figures[:4]):
        ranks[name] = i + 1
    columns = [Column("period", no_wrap=True),
               Column(f"local time ({calendar.timezone})", drop=8, no_wrap=True, squeeze=9,
                      short_header=calendar.timezone),
               *(Column(key, no_wrap=True, squeeze=7) for key in group_by),
               *(Column(name, drop=ranks[name], justify="right", no_wrap=True)
                 for name in figures)]
    table_rows: list[list[Entry]] = []
    for row in rows:
        values = _figures(row)
        groups = [_group_cell(row, key) for key in group_by]
        mark = PROVISIONAL if row.complete is False else ""
        table_rows.append([cell(row.period.id + mark), local_span(row, calendar),
                           *(Short(cell(text), cell(render.shorten(text))) for text in groups),
                           *(values[name] for name in figures)])
    if not rows:
        table_rows.append(["(no rows)", *[""] * (len(columns) - 1)])
    return fitted(cell(title), columns, table_rows, width)


# -- report-shift --------------------------------------------------------------------------------
def report_shift(
    shift_id: Annotated[str | None, typer.Argument(
        metavar="SHIFT",
        help="Shift instance, e.g. 2026-11-21/night. Default: the last completed shift.",
        show_default=False)] = None,
    html_file: Annotated[Path | None, typer.Option(
        "--html", metavar="FILE",
        help="Also write the report as one self-contained HTML file.")] = None,
    png_file: Annotated[Path | None, typer.Option(
        "--png", metavar="FILE",
        help="Also write the charts (per hour, top offenders) as a PNG.")] = None,
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
    """End-of-shift summary, compared with the shift before.

    Key figures against the previous instance of the same shift, top offenders, longest
    downtimes and activity per hour, in the calendar's zone.
    """
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
