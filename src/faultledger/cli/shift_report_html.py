"""The end-of-shift report as one self-contained HTML file and as PNG charts (matplotlib, Agg).

The HTML has its CSS inline and its charts as base64 PNG ``data:`` images, so it can be
mailed or archived as one file and opened without a network.
"""

from __future__ import annotations

import base64
import io
from html import escape

from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from faultledger.cli.render import severity_name
from faultledger.cli.shift_report import (
    TOP,
    ShiftReport,
    change_text,
    duration,
    group_text,
    local_time,
    percent_text,
    value_text,
)

ACTIVATIONS_COLOR = "#c0392b"
CONFIRMATIONS_COLOR = "#e69f00"
DPI = 100

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 2em;
       color: #1d2733; max-width: 70em; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.15em; margin-top: 1.6em; border-bottom: 1px solid #d0d7de; }
p.meta { margin: 0.2em 0; color: #4b5866; }
p.warn { color: #9a6700; font-weight: 600; }
table { border-collapse: collapse; margin: 0.5em 0; }
th, td { padding: 0.3em 0.8em; border-bottom: 1px solid #e5e9ee; text-align: right; }
th { background: #f3f5f7; }
td.text, th.text { text-align: left; }
td.worse { color: #b42318; } td.better { color: #1a7f37; }
img { max-width: 100%; height: auto; border: 1px solid #e5e9ee; }
footer { margin-top: 2em; color: #6b7785; font-size: 0.85em; }
"""


# -- charts --------------------------------------------------------------------------------------
def _draw_hours(ax: Axes, report: ShiftReport) -> None:
    hours = report.hours
    xs = list(range(len(hours)))
    width = 0.4
    ax.bar([x - width / 2 for x in xs], [h.activations for h in hours], width,
           label="activations", color=ACTIVATIONS_COLOR)
    ax.bar([x + width / 2 for x in xs], [h.confirmations for h in hours], width,
           label="confirmations", color=CONFIRMATIONS_COLOR)
    ax.set_xticks(xs, [h.label for h in hours], rotation=45 if len(hours) > 12 else 0,
                  ha="right" if len(hours) > 12 else "center")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title(f"{report.shift.id}: activations and confirmations per hour "
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


def _png(figure: Figure) -> bytes:
    FigureCanvasAgg(figure)  # the Agg canvas: no GUI, no pyplot state, no display needed
    out = io.BytesIO()
    figure.tight_layout()
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


def charts_png(report: ShiftReport) -> bytes:
    """Both charts in one image (``report-shift --png``)."""
    rows = max(len(report.offenders), 2)
    figure = Figure(figsize=(10, 5.5 + 0.45 * rows), dpi=DPI)
    top, bottom = figure.subplots(2, 1, height_ratios=[4, 1.5 + 0.45 * rows])
    _draw_hours(top, report)
    _draw_offenders(bottom, report)
    figure.suptitle(f"Shift report {report.shift.id} — {report.span_text}")
    return _png(figure)


# -- HTML ----------------------------------------------------------------------------------------
def _img(png: bytes, alt: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return f'<img src="data:image/png;base64,{data}" alt="{escape(alt)}">'


def _table(headers: list[str], rows: list[list[str]], text_columns: set[int],
           classes: list[list[str]] | None = None) -> str:
    def cell(tag: str, i: int, value: str, extra: str = "") -> str:
        names = " ".join(n for n in ("text" if i in text_columns else "", extra) if n)
        attr = f' class="{names}"' if names else ""
        return f"<{tag}{attr}>{escape(value)}</{tag}>"

    head = "".join(cell("th", i, h) for i, h in enumerate(headers))
    body = []
    for r, row in enumerate(rows):
        extras = classes[r] if classes else [""] * len(row)
        body.append("<tr>" + "".join(cell("td", i, v, extras[i]) for i, v in enumerate(row))
                    + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


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
    """The whole report as one HTML document."""
    shift = report.shift
    previous = report.previous.id if report.previous else "previous"
    figure_rows, figure_classes = [], []
    for item in report.figures:
        figure_rows.append([item.label, value_text(item.kind, item.value),
                            value_text(item.kind, item.previous), change_text(item),
                            percent_text(item)])
        trend = _trend(item.key, item.change)
        figure_classes.append(["", "", "", trend, trend])
    offender_rows = [[str(rank), group_text(r, "code"), str(r.activations),
                      str(r.confirmations), str(r.failed_reports), duration(r.active_seconds),
                      duration(r.mttr_seconds)]
                     for rank, r in enumerate(report.offenders, 1)]
    downtime_rows = [[d.fault_code, d.source_id, severity_name(d.severity),
                      local_time(report, d.start), local_time(report, d.end),
                      duration(d.seconds_in_range), duration(d.seconds)]
                     for d in report.downtimes]
    hour_rows = [[h.label, str(h.activations), str(h.confirmations)] for h in report.hours]
    notes = []
    if report.in_progress:
        notes.append(f'<p class="warn">In progress: figures up to '
                     f"{escape(local_time(report, report.as_of))}.</p>")
    if shift.seconds != report.nominal_seconds:
        notes.append('<p class="warn">This shift\'s length differs from its nominal length '
                     "because of a daylight saving time change.</p>")
    compared = (f"Compared with {escape(previous)}." if report.previous
                else "No previous instance of this shift to compare with.")
    sections = [
        f"<h1>Shift report {escape(shift.id)}</h1>",
        f'<p class="meta">{escape(report.span_text)} — {escape(report.length_text)}</p>',
        f'<p class="meta">{compared}</p>',
        *notes,
        "<h2>Key figures</h2>",
        _table(["figure", shift.id, previous, "change", "change %"], figure_rows, {0},
               figure_classes),
        f"<h2>Top {TOP} offenders</h2>",
        "<p class=\"meta\">By activations, then confirmations.</p>",
        _table(["#", "code", "activations", "confirmations", "failed reports", "active time",
                "MTTR"], offender_rows, {1}) if offender_rows
        else "<p>No failed reports in this shift.</p>",
        _img(offenders_png(report), f"top offenders of {shift.id}"),
        "<h2>Longest downtimes</h2>",
        f'<p class="meta">CONFIRMED episodes overlapping the shift, most time inside it '
        f"first; times in {escape(report.timezone)}.</p>",
        _table(["code", "source", "severity", "confirmed at", "ended", "in shift", "episode"],
               downtime_rows, {0, 1, 2, 3, 4}) if downtime_rows
        else "<p>No fault was CONFIRMED during this shift.</p>",
        "<h2>Per hour</h2>",
        _img(hours_png(report), f"activations and confirmations per hour of {shift.id}"),
        _table(["hour", "activations", "confirmations"], hour_rows, {0}),
        f"<footer>faultledger report-shift, as of {escape(local_time(report, report.as_of))} "
        f"{escape(report.timezone)}. Definitions: docs/statistics.md.</footer>",
    ]
    body = "\n".join(sections)
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f"<title>Shift report {escape(shift.id)}</title>\n<style>{_CSS}</style>\n"
            f"</head>\n<body>\n{body}\n</body>\n</html>\n")
