"""The end-of-shift report as one self-contained HTML file and as PNG charts (matplotlib, Agg).

The HTML (templates/shift_report.html, Jinja2 with autoescape) has its CSS inline and its
charts as base64 PNG ``data:`` images, so it can be mailed or archived as one file and opened
without a network.
"""

from __future__ import annotations

import base64
import io
import textwrap
from functools import lru_cache
from typing import Any

from jinja2 import Environment, PackageLoader, StrictUndefined
from markupsafe import Markup
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from faultledger.domain.text import printable
from faultledger.domain.types import severity_name
from faultledger.reports.shift import (
    GLOSSARY,
    TOP,
    ShiftReport,
    change_text,
    counted,
    duration,
    group_text,
    local_time,
    percent_text,
    value_text,
)

ESTOPS_COLOR = "#8e1b10"
ACTIVATIONS_COLOR = "#e07b6f"
CONFIRMATIONS_COLOR = "#e69f00"
ABORTED_GOALS_COLOR = "#0072b2"
DPI = 100


# -- charts --------------------------------------------------------------------------------------
def _draw_hours(ax: Axes, report: ShiftReport) -> None:
    hours = report.hours
    xs = list(range(len(hours)))
    width = 0.27
    ax.bar([x - width for x in xs], [h.estops for h in hours], width,
           label="e-stops", color=ESTOPS_COLOR)
    ax.bar(xs, [h.aborted_goals for h in hours], width,
           label="aborted goals", color=ABORTED_GOALS_COLOR)
    ax.bar([x + width for x in xs], [h.activations for h in hours], width,
           label="activations (all faults)", color=ACTIVATIONS_COLOR)
    ax.set_xticks(xs, [h.label for h in hours], rotation=45 if len(hours) > 12 else 0,
                  ha="right" if len(hours) > 12 else "center")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title(f"{report.shift.id}: e-stops, aborted goals and activations per hour "
                 f"({report.timezone})")
    ax.set_xlabel("local hour")
    ax.legend(loc="best")
    ax.grid(axis="y", alpha=0.3)


def _draw_offenders(ax: Axes, report: ShiftReport) -> None:
    rows = list(reversed(report.offenders))  # barh draws bottom-up: the worst on top
    if not rows:
        ax.text(0.5, 0.5, "no failed reports in this shift", ha="center", va="center",
                transform=ax.transAxes)
        ax.set_axis_off()
        return
    ys = list(range(len(rows)))
    height = 0.4
    ax.barh([y + height / 2 for y in ys], [r.activations for r in rows], height,
            label="activations", color=ACTIVATIONS_COLOR)
    ax.barh([y - height / 2 for y in ys], [r.confirmations for r in rows], height,
            label="confirmations", color=CONFIRMATIONS_COLOR)
    ax.set_yticks(ys, [group_text(r, "code") for r in rows])
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title(f"top {TOP} offenders")
    ax.legend(loc="best")
    ax.grid(axis="x", alpha=0.3)


def _png(figure: Figure, top: float = 1.0) -> bytes:
    """``top``: the fraction of the height the axes may use (the rest: a text panel)."""
    FigureCanvasAgg(figure)  # the Agg canvas: no GUI, no pyplot state, no display needed
    out = io.BytesIO()
    figure.tight_layout(rect=(0.0, 0.0, 1.0, top))
    figure.savefig(out, format="png", metadata={"Software": None})
    return out.getvalue()


def hours_png(report: ShiftReport) -> bytes:
    figure = Figure(figsize=(10, 4), dpi=DPI)
    _draw_hours(figure.add_subplot(), report)
    return _png(figure)


def offenders_png(report: ShiftReport) -> bytes:
    figure = Figure(figsize=(10, 1.5 + 0.45 * max(len(report.offenders), 2)), dpi=DPI)
    _draw_offenders(figure.add_subplot(), report)
    return _png(figure)


def key_figures_lines(report: ShiftReport) -> list[str]:
    """The text panel of the PNG: the shift, its span and the main counts, so the image
    alone says what it shows."""
    row = report.row
    lines = [f"Shift {report.shift.id}: {report.span_text}",
             report.headline,
             f"{counted(row.heals, 'heal')}, {counted(row.clears, 'clear')}; fault time CONFIRMED "
             f"{duration(row.active_seconds)} (summed over faults), MTTR "
             f"{duration(row.mttr_seconds)}, MTBF {duration(row.mtbf_seconds)}",
             f"time in flood {row.flood_percent:.1f} %, "
             f"{counted(row.chattering_codes, 'chattering code')}, "
             f"{counted(row.stale_codes, 'stale code')}"]
    if report.in_progress:
        lines.append(f"in progress: figures up to {local_time(report, report.as_of)}")
    return [printable(line) for line in lines]


PANEL_WIDTH = 110
"""Characters a line of the PNG's text panel holds (monospace, 9 pt, 10 inches)."""


def charts_png(report: ShiftReport) -> bytes:
    """The key figures (a text panel: shift id, span, main counts) and both charts in one
    image (``report-shift --png``)."""
    rows = max(len(report.offenders), 2)
    panel = [part for line in key_figures_lines(report)
             for part in textwrap.wrap(line, PANEL_WIDTH, subsequent_indent="  ")]
    panel_height = 0.2 * len(panel) + 0.5
    height = 5.5 + panel_height + 0.45 * rows
    figure = Figure(figsize=(10, height), dpi=DPI)
    top, bottom = figure.subplots(2, 1, height_ratios=[4, 1.5 + 0.45 * rows])
    _draw_hours(top, report)
    _draw_offenders(bottom, report)
    figure.text(0.01, 1 - 0.15 / height, "\n".join(panel), ha="left", va="top",
                family="monospace", fontsize=9)
    return _png(figure, top=1 - panel_height / height)


# -- HTML ----------------------------------------------------------------------------------------
TEMPLATE = "shift_report.html"
"""In src/faultledger/templates/ (package data)."""

Cell = dict[str, str]
"""One table cell for the template: ``text`` and CSS ``cls`` (empty for none)."""


def _finalize(value: object) -> object:
    """Every ``{{ value }}`` of the template: text shown literally (control, format and bidi
    characters escaped visibly) before autoescape makes it HTML-safe. Markup (a macro's own
    output) is already safe and passes unchanged."""
    if isinstance(value, str) and not isinstance(value, Markup):
        return printable(value)
    return value


@lru_cache(maxsize=1)
def _environment() -> Environment:
    return Environment(loader=PackageLoader("faultledger", "templates"), autoescape=True,
                       undefined=StrictUndefined, finalize=_finalize,
                       keep_trailing_newline=True)


def _cells(values: list[str], text_columns: set[int], classes: list[str] | None = None
           ) -> list[Cell]:
    return [{"text": value,
             "cls": " ".join(n for n in ("text" if i in text_columns else "",
                                         classes[i] if classes else "") if n)}
            for i, value in enumerate(values)]


def _table(headers: list[str], rows: list[list[str]], text_columns: set[int],
           classes: list[list[str]] | None = None) -> dict[str, Any]:
    return {"headers": _cells(headers, text_columns),
            "rows": [_cells(row, text_columns, classes[r] if classes else None)
                     for r, row in enumerate(rows)]}


_BETTER_WHEN_UP = {"mtbf_seconds"}
_NEUTRAL = {"heals", "clears"}


def _trend(key: str, change: float | None) -> str:
    """CSS class of a change: ``worse`` (red) or ``better`` (green); heals and clears are
    neither, more of the others is worse except MTBF."""
    if not change or key in _NEUTRAL:
        return ""
    up_is_better = key in _BETTER_WHEN_UP
    return "better" if (change > 0) == up_is_better else "worse"


def html(report: ShiftReport) -> str:
    """The whole report as one HTML document (templates/shift_report.html; every value from
    the ledger is escaped there, never pasted into HTML here)."""
    shift = report.shift
    previous = report.previous.id if report.previous else "previous"
    figure_rows, figure_classes = [], []
    for item in report.figures:
        figure_rows.append([item.label, value_text(item.kind, item.value),
                            value_text(item.kind, item.previous), change_text(item),
                            percent_text(item)])
        trend = _trend(item.key, item.change)
        figure_classes.append(["", "", "", trend, trend])
    offender_rows = [[str(rank), group_text(r, "code"), str(r.estops), str(r.activations),
                      str(r.confirmations), str(r.failed_reports), duration(r.active_seconds),
                      duration(r.mttr_seconds)]
                     for rank, r in enumerate(report.offenders, 1)]
    downtime_rows = [[d.fault_code, d.source_id, severity_name(d.severity),
                      local_time(report, d.start), local_time(report, d.end),
                      duration(d.seconds_in_range), duration(d.seconds)]
                     for d in report.downtimes]
    hour_rows = [[h.label, str(h.estops), str(h.aborted_goals), str(h.activations),
                  str(h.confirmations)] for h in report.hours]
    context: dict[str, Any] = {
        "shift_id": shift.id,
        "shift_name": shift.name,
        "estop_codes": ", ".join(report.estop_codes),
        "span_text": report.span_text,
        "length_text": report.length_text,
        "previous_id": report.previous.id if report.previous else None,
        "notes": report.notes,
        "headline": report.headline,
        "glossary": [{"term": term, "meaning": meaning} for term, meaning in GLOSSARY],
        "in_progress_until": (local_time(report, report.as_of) if report.in_progress
                              else None),
        "dst_change": shift.seconds != report.nominal_seconds,
        "top": TOP,
        "timezone": report.timezone,
        "as_of": local_time(report, report.as_of),
        "figures": _table(["figure", shift.id, previous, "change", "change %"], figure_rows,
                          {0}, figure_classes),
        "offenders": _table(["#", "code", "e-stops", "activations", "confirmations",
                             "failed reports",
                             "active time", "MTTR"], offender_rows, {1}),
        "downtimes": _table(["code", "source", "severity", "confirmed at", "ended",
                             "in shift", "episode"], downtime_rows, {0, 1, 2, 3, 4}),
        "hours": _table(["hour", "e-stops", "aborted goals", "activations (all faults)",
                         "confirmations"], hour_rows, {0}),
        "offenders_png": base64.b64encode(offenders_png(report)).decode("ascii"),
        "hours_png": base64.b64encode(hours_png(report)).decode("ascii"),
    }
    return _environment().get_template(TEMPLATE).render(context)
