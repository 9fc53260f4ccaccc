"""Turning faults and log records into terminal tables, JSON and CSV.

Tables fit the terminal (docs/cli.md, "Tables"): each column has a rank; the columns that do
not fit are left out, or shown in a shorter form first (``Short`` cells: times without
milliseconds, long ids shortened with ``…``), highest rank first. Times are shown in the shift
calendar's zone, named in the column header.
"""

from __future__ import annotations

import io
import re
import sys
import textwrap
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import IO, Any, Literal, NamedTuple, TextIO, cast
from zoneinfo import ZoneInfo

from rich.cells import cell_len
from rich.console import Console, Group, RenderableType
from rich.table import Table
from rich.text import Text

from faultledger.cli.safe_text import cell, printable
from faultledger.domain.clock import from_ns
from faultledger.domain.events import LogRecord
from faultledger.domain.fault import Fault
from faultledger.domain.integrity import canonical_json
from faultledger.domain.projector import Transition
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.types import FaultStatus, severity_name
from faultledger.store.database import describe

_STATUS_STYLE = {
    FaultStatus.CONFIRMED: "bold red",
    FaultStatus.PREFAILED: "yellow",
    FaultStatus.PREPASSED: "cyan",
    FaultStatus.HEALED: "green",
    FaultStatus.CLEARED: "dim",
}


# -- times ---------------------------------------------------------------------------------------
def when(moment: datetime | None) -> str:
    """ISO 8601 with its offset, for JSON (machine formats keep the stored instant)."""
    return "-" if moment is None else moment.isoformat(timespec="milliseconds")


def stamp(moment: datetime | None, zone: ZoneInfo, *, ms: bool = True,
          seconds: bool = True) -> str:
    """A time for a person, in ``zone`` (the calendar's; the header or text names it):
    ``2026-11-21 22:10:00.250``. A wall-clock time that happens twice (the hour repeated when
    daylight saving time ends) carries its abbreviation: ``2026-10-25 02:30:00 CEST``."""
    if moment is None:
        return "-"
    local = moment.astimezone(zone)
    text = local.strftime("%Y-%m-%d %H:%M:%S" if seconds else "%Y-%m-%d %H:%M")
    if ms and seconds:
        text += f".{local.microsecond // 1000:03d}"
    return text + (f" {local:%Z}" if ambiguous(local) else "")


def clock(moment: datetime, zone: ZoneInfo) -> str:
    """Only the local clock time, ``22:10:00`` (the date is known from the context)."""
    local = moment.astimezone(zone)
    return f"{local:%H:%M:%S}" + (f" {local:%Z}" if ambiguous(local) else "")


def ambiguous(local: datetime) -> bool:
    """Whether this local wall-clock time occurs twice in its zone (the fall-back hour)."""
    return local.replace(fold=1 - local.fold).utcoffset() != local.utcoffset()


def zoned(moment: datetime | None, calendar: ShiftCalendar, *, ms: bool = False) -> str:
    """A time in running text, followed by its zone: ``2026-11-21 22:00:00 Europe/Berlin``."""
    return "-" if moment is None else f"{stamp(moment, calendar.zone, ms=ms)} {calendar.timezone}"


ROOMY = 120
"""From this width on (and with ``--wide``) a time column's header takes one line."""


def time_header(label: str, calendar: ShiftCalendar, cells: int = 19,
                room: int | None = None) -> str:
    """``occurred (Europe/Berlin)``: on two lines when the zone's name would widen a column
    of ``cells`` in a table that has to fit in ``room`` (less than 120 columns)."""
    one_line = f"{label} ({calendar.timezone})"
    if cell_len(one_line) <= cells or room is None or room >= ROOMY:
        return one_line
    return f"{label}\n({calendar.timezone})"


# -- ids -----------------------------------------------------------------------------------------
ID_WIDTH = 24
"""Codes, sources and actions longer than this are shortened in narrow tables (``--wide``
shows them whole)."""


def shorten(text: str, width: int = ID_WIDTH) -> str:
    """``HW_LEFT_ARM…ERGENCY_STOP``: the start and the end of a long id, which tell ids apart
    better than the start alone."""
    if cell_len(text) <= width:
        return text
    keep = width - 1
    head = keep // 2
    return text[:head] + "…" + text[len(text) - (keep - head):]


def short_goal(goal_id: str) -> str:
    """A goal UUID as its first 8 hex digits (``3f2a9c1e…``), as git shortens hashes."""
    return goal_id if len(goal_id) <= 12 else goal_id[:8] + "…"


# -- JSON ----------------------------------------------------------------------------------------
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
        "first_occurred_ever": when(from_ns(fault.first_ever_ns)) if fault.first_ever_ns
        else None,
        "episode": fault.episode,
        "occurrences_in_episode": fault.episode_failures,
        "occurrences_total": fault.total_failures,
        "acknowledged": None if fault.acknowledged is None else {
            "by": fault.acknowledged.actor, "at": when(from_ns(fault.acknowledged.at_ns)),
            "note": fault.acknowledged.note, "seq": fault.acknowledged.seq},
        "shelved": None if fault.shelved is None else {
            "by": fault.shelved.actor, "at": when(from_ns(fault.shelved.at_ns)),
            "until": when(from_ns(fault.shelved.until_ns)), "reason": fault.shelved.reason,
            "seq": fault.shelved.seq},
    }


# -- fitting tables ------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Column:
    """A table column that may be left out, or shown shorter, when the terminal is narrow.

    ``drop``: 0 = always shown; otherwise the column with the highest ``drop`` is left out
    first. ``squeeze``: the rank at which the column's ``Short`` cells switch to their short
    form (and the header to ``short_header``); drops and squeezes run in one order, highest
    rank first, until the table fits. ``no_wrap`` cells (codes, statuses, ids, times) are never
    split; the others fold, at spaces first, down to ``cap`` characters.
    """

    header: str
    drop: int = 0
    no_wrap: bool = False
    justify: Literal["left", "right", "center"] = "left"
    cap: int = 14
    squeeze: int = 0
    short_header: str | None = None
    least: int = 0
    """The narrowest a folding column may get (details worth reading on few lines)."""


Cell = Text | str


class Short(NamedTuple):
    """A cell with a shorter form for narrow terminals (see ``Column.squeeze``)."""

    full: Cell
    short: Cell


Entry = Cell | Short
_BORDERS = 1
"""Characters of a table's outer border on one side; each column adds padding and a rule."""


def _plain(value: Cell) -> str:
    return value.plain if isinstance(value, Text) else value


def _form(value: Entry, squeezed: bool) -> Cell:
    if isinstance(value, Short):
        return value.short if squeezed else value.full
    return value


def _floor(column: Column, header: str, cells: Iterable[Cell]) -> int:
    """The narrowest this column can be without splitting what must not be split."""
    texts = [header, *(_plain(c) for c in cells)]
    if column.no_wrap:
        return max(cell_len(line) for t in texts for line in t.splitlines() or [""])
    heads = [cell_len(line) for line in header.splitlines()] or [0]
    words = [cell_len(w) for t in texts[1:] for w in t.split()] or [1]
    longest = max(cell_len(t) for t in texts[1:]) if texts[1:] else 0
    return max(min(max(words), column.cap), min(column.least, longest), *heads)


def table_width(widths: Iterable[int]) -> int:
    """The width of a default-box table whose columns have these content widths."""
    items = list(widths)
    return sum(items) + 3 * len(items) + _BORDERS


@dataclass(frozen=True, slots=True)
class Plan:
    keep: list[int]
    squeezed: set[int]
    fits: bool


def plan(columns: Sequence[Column], rows: Sequence[Sequence[Entry]],
         width: int | None) -> Plan:
    """Which columns to show and which in their short form so the table fits ``width``."""
    keep = list(range(len(columns)))
    squeezed: set[int] = set()

    def needed() -> int:
        return table_width(
            _floor(columns[i], _header(columns[i], i in squeezed),
                   (_form(row[i], i in squeezed) for row in rows)) for i in keep)

    if width is None:
        return Plan(keep, squeezed, True)
    steps = sorted([(c.drop, 0, i) for i, c in enumerate(columns) if c.drop]
                   + [(c.squeeze, 1, i) for i, c in enumerate(columns) if c.squeeze],
                   key=lambda step: (-step[0], -step[1]))
    for _, squeeze, index in steps:
        if needed() <= width:
            break
        if index not in keep:
            continue
        if squeeze:
            squeezed.add(index)
        else:
            keep.remove(index)
    return Plan(keep, squeezed, needed() <= width)


def _header(column: Column, squeezed: bool) -> str:
    return column.short_header if squeezed and column.short_header else column.header


def fitted(title: Cell, columns: Sequence[Column], rows: Sequence[Sequence[Entry]],
           width: int | None) -> RenderableType:
    """A table of the columns that fit in ``width`` (None: every column in full, ``--wide``),
    leaving out or shortening columns, highest rank first, until it fits."""
    return build(title, columns, rows, plan(columns, rows, width), width)


def fitted_first(title: Cell,
                 layouts: Sequence[tuple[Sequence[Column], Sequence[Sequence[Entry]]]],
                 width: int | None) -> RenderableType:
    """The first layout that fits ``width`` (after its own squeezes and drops); else the last
    one, fitted as well as it can be."""
    for columns, rows in layouts[:-1]:
        chosen = plan(columns, rows, width)
        if chosen.fits:
            return build(title, columns, rows, chosen, width)
    return fitted(title, *layouts[-1], width)


def build(title: Cell, columns: Sequence[Column], rows: Sequence[Sequence[Entry]],
          chosen: Plan, width: int | None = None) -> RenderableType:
    """The table under its title; the title is wrapped to ``width`` by ``wrap`` (never inside
    a time), not by rich to the table's width."""
    heading = Text("\n".join(wrap(_plain(title), width)), style="italic")
    if isinstance(title, Text) and title.style:
        heading.stylize(title.style)
    table = Table(title=None)
    for i in chosen.keep:
        c = columns[i]
        squeezed = i in chosen.squeezed
        cells = [_form(row[i], squeezed) for row in rows]
        header = _header(c, squeezed)
        table.add_column(header, justify=c.justify, no_wrap=c.no_wrap,
                         overflow="ellipsis" if c.no_wrap else "fold",
                         min_width=_floor(c, header, cells) if c.no_wrap else None)
    for row in rows:
        table.add_row(*(_form(row[i], i in chosen.squeezed) for i in chosen.keep))
    return Group(heading, table)


_TIME_SPACE = re.compile(r"(?<=\d{4}-\d{2}-\d{2}) (?=\d{2}:\d{2})")
"""The space between a date and its time: never a place to break a line."""
_GLUE = "\x00"


def wrap(text: str, width: int | None) -> list[str]:
    """``text`` in lines of at most ``width`` cells, broken at spaces but never between a
    date and its time (``2026-11-21 22:00:00`` stays on one line); None: one line."""
    if width is None or cell_len(text) <= width:
        return [text]
    glued = _TIME_SPACE.sub(_GLUE, text)
    lines = textwrap.wrap(glued, max(width, 20), break_on_hyphens=False) or [""]
    return [line.replace(_GLUE, " ") for line in lines]


# -- the tables ----------------------------------------------------------------------------------
def faults_table(faults: Iterable[Fault], title: str, calendar: ShiftCalendar,
                 width: int | None = None) -> RenderableType:
    """Every value from outside (code, sources, description, title) is shown literally:
    ``safe_text.cell``, never markup, never a control character. Columns that do not fit in
    ``width`` go first: sources, description, counter, count, the milliseconds of last
    occurred, who acknowledged and when ("-": nobody yet), last occurred, severity."""
    zone = calendar.zone
    columns = (Column("code", no_wrap=True), Column("status", no_wrap=True),
               Column("severity", drop=1, no_wrap=True),
               Column("acknowledged", drop=3, cap=16),
               Column("count", drop=5, justify="right"),
               Column("counter", drop=6, justify="right"),
               Column(time_header("last occurred", calendar, 23, width), drop=2,
                      no_wrap=True, squeeze=4,
                      short_header=time_header("last occurred", calendar, 19, width)),
               Column("sources", drop=8), Column("description", drop=7))
    rows: list[list[Entry]] = [
        [cell(f.fault_code), cell(f.status.value, _STATUS_STYLE[f.status]),
         severity_name(f.severity),
         cell(acknowledged(f, zone)),
         str(f.occurrence_count), str(f.debounce_counter),
         Short(stamp(f.last_occurred, zone), stamp(f.last_occurred, zone, ms=False)),
         cell(", ".join(f.reporting_sources)), cell(f.description)]
        for f in faults]
    return fitted(cell(title), columns, rows, width)


def acknowledged(fault: Fault, zone: ZoneInfo) -> str:
    """Who acknowledged the fault's episode and when (``-``: nobody yet)."""
    ack = fault.acknowledged
    return "-" if ack is None else f"{ack.actor} {stamp(from_ns(ack.at_ns), zone, seconds=False)}"


def episode_lines(fault: Fault, calendar: ShiftCalendar) -> list[str]:
    """`show`'s lines on the fault's episodes and what people did about it."""
    def at(ns: int) -> str:
        return zoned(from_ns(ns), calendar)

    lines = [f"episode {fault.episode} since {at(fault.first_occurred_ns)}; first occurred "
             f"{at(fault.first_ever_ns or fault.first_occurred_ns)}; occurrences (FAILED "
             f"reports): {fault.episode_failures} in this episode, {fault.total_failures} "
             "in total"]
    ack = fault.acknowledged
    if ack is not None:
        lines.append(f"acknowledged {at(ack.at_ns)} by {ack.actor}"
                     + (f": {ack.note}" if ack.note else ""))
    elif fault.is_active:
        lines.append("not acknowledged")
    shelf = fault.shelved
    if shelf is not None:
        lines.append(f"shelved {at(shelf.at_ns)} by {shelf.actor} until {at(shelf.until_ns)}"
                     + (f": {shelf.reason}" if shelf.reason else ""))
    return lines


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
    if record.kind == "ledger_identified":
        return f"robot {p['robot_id']}, ledger {p['ledger_id']}"
    if record.kind == "fault_acknowledged":
        return (f"acknowledged by {p['actor']} (episode {p['episode']})"
                + (f": {p['note']}" if p["note"] else ""))
    if record.kind == "fault_shelved":
        return (f"shelved by {p['actor']} until {when(from_ns(p['until_ns']))}"
                + (f": {p['reason']}" if p["reason"] else ""))
    if record.kind == "fault_unshelved":
        return f"unshelved by {p['actor']}" + (f": {p['reason']}" if p["reason"] else "")
    return str(p.get("reason", ""))


def _subject_and_details(record: LogRecord, room: int) -> tuple[str, str]:
    """What a narrow history row shows in its one ``code / details`` column: the fault code
    (or a goal's action, or the log's robot) and the details; ids longer than ``room`` are
    shortened."""
    p = record.payload
    if record.kind == "goal_outcome":
        return (shorten(str(p["action"]), room),
                f"{p['status']} goal {short_goal(str(p['goal_id']))}")
    if record.kind == "ledger_identified":  # the robot, over its log's short id
        return (shorten(str(p["robot_id"]), room),
                f"ledger {short_goal(str(p['ledger_id']))}")
    if record.kind == "fault_cleared":
        reason = f": {p['reason']}" if p["reason"] else ""
        return (shorten(record.fault_code or "", room),
                f"cleared by {shorten(str(p['actor']), room)}{reason}")
    return shorten(record.fault_code or "", room), summary(record)


KIND_WIDTH = 16


def _kind_lines(kind: str) -> str:
    """A record kind on lines of at most 16 characters, broken after an underscore
    (``fault_confirmed_`` / ``by_timer``); the common kinds fit on one."""
    if len(kind) <= KIND_WIDTH:
        return kind
    cut = kind.rindex("_", 0, KIND_WIDTH) + 1
    return kind[:cut] + "\n" + _kind_lines(kind[cut:])


def history_table(records: Iterable[LogRecord], calendar: ShiftCalendar,
                  width: int | None = None) -> RenderableType:
    """The log, one row per record. Wide: seq, occurred, kind, code, source, details (source
    goes first). Narrow (an 80-column terminal): seq, occurred (without milliseconds), kind and
    one column with the code (or a goal's action) over the details, long ids shortened."""
    zone = calendar.zone
    items = list(records)
    wide_columns = (Column("seq", no_wrap=True, justify="right"),
                    Column(time_header("occurred", calendar, 23, width), no_wrap=True),
                    Column("kind", no_wrap=True), Column("code", no_wrap=True),
                    Column("source", drop=1), Column("details", cap=16, least=36))
    wide_rows: list[list[Entry]] = [
        [str(r.seq), stamp(r.occurred_at, zone), cell(r.kind), cell(r.fault_code or ""),
         cell(r.source_id or ""), cell(summary(r))] for r in items]
    narrow_columns = (Column("seq", no_wrap=True, justify="right"),
                      Column(time_header("occurred", calendar, 19, width), drop=1,
                             no_wrap=True),
                      Column("kind", drop=2, no_wrap=True),
                      Column("code / details", cap=ID_WIDTH))
    fixed = [[str(r.seq), stamp(r.occurred_at, zone, ms=False), _kind_lines(r.kind)]
             for r in items]
    room = ID_WIDTH
    if width is not None:  # the codes get what the other columns leave, at least 24
        floors = [_floor(c, c.header, (row[i] for row in fixed))
                  for i, c in enumerate(narrow_columns[:3])]
        room = max(ID_WIDTH, width - table_width([*floors, 0]))
    narrow_columns = (*narrow_columns[:3], Column("code / details", cap=room))
    narrow_rows: list[list[Entry]] = []
    for r, (seq, occurred, kind) in zip(items, fixed, strict=True):
        subject, details = _subject_and_details(r, room)
        text = Text(printable(subject), style="bold") if subject else Text()
        if subject and details:
            text.append("\n")
        text.append(printable(details))
        kind_cell = Text("\n").join(cell(line) for line in kind.split("\n"))  # lines kept
        narrow_rows.append([seq, occurred, kind_cell, text])
    return fitted_first("fault log", [(wide_columns, wide_rows),
                                      (narrow_columns, narrow_rows)], width)


def transitions_table(items: Iterable[Transition], calendar: ShiftCalendar,
                      width: int | None = None, reasons: dict[int, str] | None = None
                      ) -> RenderableType:
    """Narrower first: a long ``by`` shortened, cause left out (a clear's reason is also on
    `show`'s "last cleared" line), at without milliseconds, then at and by left out.
    ``reasons``: the clear reason of a seq, shown after its cause."""
    why = reasons or {}
    zone = calendar.zone
    columns = (Column("seq", no_wrap=True, justify="right"),
               Column(time_header("at", calendar, 23, width), drop=2, no_wrap=True, squeeze=5),
               Column("from", no_wrap=True), Column("to", no_wrap=True),
               Column("cause", drop=6), Column("by", drop=1, no_wrap=True, squeeze=7))
    rows: list[list[Entry]] = [
        [str(t.seq), Short(stamp(from_ns(t.at_ns), zone), stamp(from_ns(t.at_ns), zone,
                                                                ms=False)),
         t.from_status.value if t.from_status else "(new)", t.to_status.value,
         cell(f"{t.cause}: {why[t.seq]}" if why.get(t.seq) else t.cause),
         Short(cell(t.source_id), cell(shorten(t.source_id)))]
        for t in items]
    return fitted("status transitions", columns, rows, width)


def describe_url(url: str) -> str:
    return describe(url)


# -- output --------------------------------------------------------------------------------------
def note(message: str, label: str = "note:") -> None:
    """``note: …`` on stderr: on a terminal wrapped at spaces (never inside a time), indented
    under its first line; piped, one line (scripts grep it whole)."""
    err = Console(stderr=True, highlight=False, soft_wrap=True)
    if not err.is_terminal:
        complain(label, message)
        return
    lines = wrap(f"{label} {printable(message)}", err.width)
    first, rest = lines[0], lines[1:]
    head = first[len(label) + 1:]
    indent = " " * (len(label) + 1)
    err.print(Text.assemble((label, "bold yellow"), " ", head))
    for line in wrap(" ".join(rest), err.width - len(indent)) if rest else []:
        err.print(Text(indent + line))


def warn(message: str) -> None:
    """``warning: …`` on stderr, laid out as ``note`` lays out its notes."""
    note(message, "warning:")


def complain(label: str, message: str) -> None:
    """One line on stderr: the label in red, the operator's text verbatim (never as markup,
    never wrapped, so brackets survive and the line stays greppable; control characters it
    quotes are shown escaped, see ``safe_text.printable``)."""
    Console(stderr=True, highlight=False, soft_wrap=True).print(
        Text.assemble((printable(label), "bold red"), " ", printable(message)))


PIPE_WIDTH = 200
"""Tables written to a pipe or file are laid out for this many columns; their lines carry no
padding."""
WIDE = 1000
"""The console width of ``--wide``: no table is cut to fit."""


class _Unpadded(io.TextIOBase):
    """A text stream that drops the spaces rich pads lines with (a title padded to the
    console's width, a table's blank cells at the end of a line)."""

    def __init__(self, target: TextIO) -> None:
        super().__init__()
        self._target = target
        self._pending = ""

    def write(self, text: str) -> int:
        lines = (self._pending + text).split("\n")
        self._pending = lines.pop()
        for line in lines:
            self._target.write(line.rstrip(" ") + "\n")
        return len(text)

    def flush(self) -> None:
        if self._pending:  # a line not ended yet: written as it is (rich ends its lines)
            self._target.write(self._pending)
            self._pending = ""
        self._target.flush()

    def isatty(self) -> bool:
        return self._target.isatty()

    def fileno(self) -> int:
        return self._target.fileno()

    @property
    def encoding(self) -> str:  # type: ignore[override]
        return getattr(self._target, "encoding", "utf-8")


def console(stderr: bool = False, *, wide: bool = False) -> Console:
    """Rich console for tables. A terminal: its width. A pipe or file: 200 columns, whatever
    COLUMNS says (a Python parent process that loaded readline exports its own terminal's
    width there), and no line is padded with trailing spaces. ``wide`` (``--wide``): as wide
    as the widest table, every column (the terminal wraps what is wider)."""
    target = sys.stderr if stderr else sys.stdout
    probe = Console(file=target)
    width = None if probe.is_terminal else PIPE_WIDTH
    if wide:
        width = max(probe.width, WIDE)
    return Console(file=cast(IO[str], _Unpadded(target)), highlight=False, soft_wrap=False,
                   width=width)


def say(text: str) -> None:
    """One line of text on stdout, shown literally: wrapped at word boundaries to a terminal's
    width, a single unwrapped line when piped (scripts read it whole)."""
    out = console()
    if out.is_terminal:
        out.print(cell(text))
        out.file.flush()
    else:
        print(printable(text), flush=True)


def fit_width(out: Console, wide: bool) -> int | None:
    """The width tables are fitted to on ``out``: None (every column) with ``--wide``."""
    return None if wide else out.width
