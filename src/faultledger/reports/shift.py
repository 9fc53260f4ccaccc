"""The end-of-shift report: one shift instance's figures next to the previous shift's.

Every number comes from the FaultLedger API (``stats``, ``downtimes``); this module only
picks rows, compares them (difference and percent change) and formats values as text. The
terminal rendering is ``cli/shift_report.py``, the HTML and PNG ones ``shift_html.py``, the
JSON one (``GET /api/v1/shift-report?format=json``, which the dashboard shows) ``as_dict``.

"Previous shift" has one definition for every view (``previous_shift``; docs/statistics.md):
the previous instance of the *same* shift, the night before a night, so a trend compares
like with like (a night shift is not a morning shift with fewer people).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

from faultledger.domain.shifts import Period, ShiftCalendar, ShiftInstance
from faultledger.domain.stat_rows import StatsRow
from faultledger.domain.types import severity_name
from faultledger.errors import InvalidInputError
from faultledger.service.ledger import FaultLedger
from faultledger.service.results import Downtime

TOP = 10
"""Offenders and downtimes shown."""
SEARCH_BACK = timedelta(days=14)
"""How far back the default shift (the last completed one) is looked for."""

KEY_FIGURES: tuple[tuple[str, str, str], ...] = (
    ("estops", "e-stops", "count"),
    ("aborted_goals", "aborted goals", "count"),
    ("activations", "activations (all faults)", "count"),
    ("failed_reports", "failed reports", "count"),
    ("confirmations", "confirmations", "count"),
    ("heals", "heals", "count"),
    ("clears", "clears", "count"),
    ("active_seconds", "fault time CONFIRMED (sum)", "duration"),
    ("mttr_seconds", "MTTR", "duration"),
    ("mtbf_seconds", "MTBF", "duration"),
    ("flood_percent", "time in flood", "percent"),
    ("chattering_codes", "chattering codes", "count"),
    ("stale_codes", "stale codes", "count"),
    ("acknowledgements", "acknowledgements", "count"),
    ("mtta_seconds", "MTTA", "duration"),
    ("shelved_seconds", "time shelved (sum)", "duration"),
)
"""(StatsRow field, label, kind) of the figures compared with the previous shift."""

GLOSSARY: tuple[tuple[str, str], ...] = (
    ("e-stops", "activations of the e-stop codes (the config's estop_codes, by default the "
     "hardware bridge's HW_*_EMERGENCY_STOP): one press of an emergency stop is one e-stop, "
     "however often it is re-reported while held"),
    ("activations (all faults)", "FAILED edges of every fault, e-stops included: a FAILED "
     "report whose previous report of the same code was not FAILED (or the first ever, or "
     "the first after a clear)"),
    ("failed reports", "every FAILED report stored, repeats included (a held e-stop "
     "re-reported each second is many failed reports, one activation)"),
    ("aborted goals", "action goals that ended ABORTED, each goal once"),
    ("previous shift", "the previous instance of the same shift (the night before for a "
     "night), so a trend compares like with like"),
    ("confirmations", "changes to CONFIRMED: a fault passed its debounce threshold (or was "
     "CRITICAL, or stayed PREFAILED past the timer)"),
    ("heals", "changes to HEALED: the fault's reporter said PASSED often enough"),
    ("clears", "changes to CLEARED: an operator cleared the fault (or startup did)"),
    ("fault time CONFIRMED", "time faults spent CONFIRMED in the shift, summed over faults: "
     "two faults CONFIRMED for one hour at once count two hours, so it can exceed the shift"),
    ("MTTR", "mean time to repair: the mean length of the CONFIRMED episodes that ended "
     "(HEALED or CLEARED) in the shift, from their start, which may be before the shift"),
    ("MTBF", "mean time between failures: shift length / confirmations"),
    ("time in flood", "% of the shift in 10-minute windows with more than 10 confirmations "
     "(ISA-18.2 alarm flood)"),
    ("chattering codes", "codes with 3 activations in less than 60 s"),
    ("stale codes", "codes CONFIRMED for 24 h or more at some moment of the shift"),
    ("acknowledgements", "faults whose episode an operator acknowledged in the shift "
     "(faultledger ack, the dashboard, HTTP, ROS); a new episode needs a new one"),
    ("MTTA", "mean time to acknowledge: from an episode's first confirmation to its "
     "acknowledgement, over the acknowledgements in the shift"),
    ("time shelved", "time faults spent shelved (hidden as known nuisances) in the shift, "
     "summed over faults"),
)
"""(term, meaning) of every figure the report shows: `report-shift --glossary`, the HTML.
The definitions in full: docs/statistics.md."""


@dataclass(frozen=True, slots=True)
class Comparison:
    """One figure of this shift and of the previous instance of the same shift."""

    key: str
    label: str
    kind: str
    """count, duration (seconds) or percent."""
    value: float | None
    previous: float | None

    @property
    def change(self) -> float | None:
        if self.value is None or self.previous is None:
            return None
        return self.value - self.previous

    @property
    def change_percent(self) -> float | None:
        """Relative change; None when there is nothing to compare with (previous 0 or none)."""
        change = self.change
        if change is None or not self.previous:
            return None
        return change / self.previous * 100.0


@dataclass(frozen=True, slots=True)
class HourBar:
    label: str
    """Local clock hour (``02:00 CEST`` / ``02:00 CET`` on a fall-back night)."""
    start: datetime
    activations: int
    confirmations: int
    aborted_goals: int = 0
    estops: int = 0


@dataclass(frozen=True, slots=True)
class ShiftReport:
    shift: ShiftInstance
    timezone: str
    nominal_seconds: float
    as_of: datetime
    row: StatsRow
    previous: ShiftInstance | None
    previous_row: StatsRow | None
    figures: tuple[Comparison, ...]
    offenders: tuple[StatsRow, ...]
    """Code rows, most activations first, then most confirmations."""
    downtimes: tuple[Downtime, ...]
    hours: tuple[HourBar, ...]
    calendar: ShiftCalendar
    estop_codes: tuple[str, ...] = ()
    """The globs that made ``estops`` (the ledger's configuration)."""

    @property
    def in_progress(self) -> bool:
        return self.as_of < self.shift.end

    def local(self, moment: datetime) -> datetime:
        return moment.astimezone(self.calendar.zone)

    @property
    def span_text(self) -> str:
        """``Sat 2026-11-21 22:00 – Sun 2026-11-22 06:00 Europe/Berlin``."""
        start, end = self.local(self.shift.start), self.local(self.shift.end)
        return f"{start:%a %Y-%m-%d %H:%M} – {end:%a %Y-%m-%d %H:%M} {self.timezone}"

    def figure(self, key: str) -> float | None:
        return next((f.value for f in self.figures if f.key == key), None)

    @property
    def headline(self) -> str:
        """E-stops and aborted goals first, then the rest in one line: ``5 e-stops, 3 aborted
        goals; 7 activations of all faults from 12 failed reports, 4 confirmations``."""
        row = self.row
        return (f"{counted(row.estops, 'e-stop')}, {counted(row.aborted_goals, 'aborted goal')}"
                f"; {counted(row.activations, 'activation')} of all faults from "
                f"{counted(row.failed_reports, 'failed report')}, "
                f"{counted(row.confirmations, 'confirmation')}")

    @property
    def notes(self) -> tuple[str, ...]:
        """Why a figure may look impossible: every duration that can exceed the shift says
        why when it does (fault time CONFIRMED summed over faults, MTTR and episodes that
        started before the shift)."""
        found: list[str] = []
        active = self.figure("active_seconds")
        elapsed = (min(self.as_of, self.shift.end) - self.shift.start).total_seconds()
        if active is not None and active > elapsed > 0:
            found.append(f"fault time CONFIRMED ({duration(active)}) is summed over faults: "
                         f"several were CONFIRMED at the same time, so it exceeds the "
                         f"{duration(elapsed)} of the shift; see the downtimes below")
        mttr = self.figure("mttr_seconds")
        if mttr is not None and mttr > elapsed > 0:
            found.append(f"MTTR ({duration(mttr)}) exceeds the {duration(elapsed)} of the "
                         f"shift: it is the whole length of the episodes repaired in the "
                         f"shift, which started before it")
        if any(d.seconds > elapsed > 0 for d in self.downtimes):
            found.append("a downtime's episode is longer than the shift: it started before "
                         "the shift or lasted past it; \"in shift\" is the part inside")
        return tuple(found)

    @property
    def length_text(self) -> str:
        """``8h``, or ``9h (nominal 8h: daylight saving time change)``."""
        text = duration(self.shift.seconds)
        if self.shift.seconds != self.nominal_seconds:
            text += (f" (nominal {duration(self.nominal_seconds)}: daylight saving time "
                     f"change)")
        return text


# -- building ------------------------------------------------------------------------------------
def previous_shift(calendar: ShiftCalendar, shift: ShiftInstance) -> ShiftInstance | None:
    """THE previous shift of every view: the previous instance of the same shift name (the
    night before a night; after a weekend without that shift, the last day it ran)."""
    return calendar.previous(shift)


def last_completed(calendar: ShiftCalendar, now: datetime) -> ShiftInstance:
    """The shift instance before the one containing ``now`` (the last one ended by ``now``
    when ``now`` is unscheduled time)."""
    current = calendar.shift_at(now)
    before = current.start if current is not None else now
    ended = [i for i in calendar.instances(before - SEARCH_BACK, before) if i.end <= before]
    if not ended:
        raise InvalidInputError(f"no shift ended in the {SEARCH_BACK.days} days before "
                                f"{before.astimezone(calendar.zone):%Y-%m-%d %H:%M}")
    return ended[-1]


def nominal_seconds(calendar: ShiftCalendar, shift: ShiftInstance) -> float:
    """The shift's length by its definition's clock times (what it lasts without DST)."""
    for definition in calendar.shifts_on(shift.production_day):
        if definition.name == shift.name:
            start = definition.start.hour * 60 + definition.start.minute
            end = definition.end.hour * 60 + definition.end.minute
            return float(((end - start) % 1440 or 1440) * 60)
    return shift.seconds


def build_report(ledger: FaultLedger, calendar: ShiftCalendar, shift_id: str | None,
                 as_of: datetime | None = None) -> ShiftReport:
    """The report of shift ``shift_id`` (default: the last completed one) as of ``as_of``.

    A shift still running at ``as_of`` (default now) is counted up to ``as_of`` itself (a
    range with no end: what happened a second ago is in), not up to its planned end.
    """
    now = as_of or datetime.now(UTC)
    if shift_id is None:
        shift = last_completed(calendar, now)
    else:
        try:
            shift = calendar.parse_id(shift_id)
        except ValueError as error:
            raise InvalidInputError(str(error)) from None
        if shift.start > now:
            raise InvalidInputError(f"shift {shift.id} has not started yet (it starts "
                                    f"{shift.start.astimezone(calendar.zone):%Y-%m-%d %H:%M})")
    previous = previous_shift(calendar, shift)
    until = shift.end if shift.end <= now else None
    row = _shift_row(ledger, calendar, shift, now, until)
    previous_row = (None if previous is None
                    else _shift_row(ledger, calendar, previous, now, previous.end))
    figures = tuple(
        Comparison(key, label, kind, getattr(row, key),
                   None if previous_row is None else getattr(previous_row, key))
        for key, label, kind in KEY_FIGURES)
    by_code = [r for r in ledger.stats("shift", shift.start, until, group_by=["code"],
                                       calendar=calendar, as_of=now)
               if r.period.id == shift.id
               and (r.activations or r.confirmations or r.failed_reports)]
    by_code.sort(key=lambda r: (-r.activations, -r.confirmations, str(r.group["code"])))
    hours = ledger.stats("hour", shift.start, until, calendar=calendar, as_of=now)
    return ShiftReport(
        shift=shift, timezone=calendar.timezone,
        nominal_seconds=nominal_seconds(calendar, shift), as_of=now, row=row,
        previous=previous, previous_row=previous_row, figures=figures,
        offenders=tuple(by_code[:TOP]),
        downtimes=tuple(ledger.downtimes(shift.start, shift.end, TOP, as_of=now)),
        hours=_hour_bars(hours, calendar), calendar=calendar,
        estop_codes=ledger.estop_codes)


def _shift_row(ledger: FaultLedger, calendar: ShiftCalendar, shift: ShiftInstance,
               as_of: datetime, until: datetime | None) -> StatsRow:
    rows = ledger.stats("shift", shift.start, until, calendar=calendar, as_of=as_of)
    for row in rows:
        if row.period.id == shift.id:
            return row
    # Not reachable with a valid calendar: the range is exactly the instance.
    return StatsRow(Period(shift.id, shift.name, shift.production_day, shift.start, shift.end))


def _hour_bars(rows: list[StatsRow], calendar: ShiftCalendar) -> tuple[HourBar, ...]:
    zone = calendar.zone
    labels = [f"{r.period.start.astimezone(zone):%H:%M}" for r in rows]
    repeated = Counter(labels)
    return tuple(
        HourBar(label if repeated[label] == 1
                else f"{label} {r.period.start.astimezone(zone):%Z}",
                r.period.start, r.activations, r.confirmations, r.aborted_goals, r.estops)
        for label, r in zip(labels, rows, strict=True))


# -- formatting ----------------------------------------------------------------------------------
def counted(count: int, noun: str) -> str:
    """``1 e-stop``, ``2 e-stops``, ``0 aborted goals``: plurals right."""
    return f"{count} {noun}" if count == 1 else f"{count} {noun}s"


def duration(seconds: float | None) -> str:
    """Human-readable: ``45.0s``, ``12m 05s``, ``3h 02m``, ``8h``, ``2d 04h``; ``-`` for None."""
    if seconds is None:
        return "-"
    if seconds < 60:
        return f"{seconds:.1f}s"
    whole = round(seconds)
    if whole < 3600:
        return f"{whole // 60}m {whole % 60:02d}s"
    if whole < 86400:
        hours, rest = divmod(whole, 3600)
        return f"{hours}h" if rest == 0 else f"{hours}h {rest // 60:02d}m"
    days, rest = divmod(whole, 86400)
    return f"{days}d {rest // 3600:02d}h"


def value_text(kind: str, value: float | None) -> str:
    if value is None:
        return "-"
    if kind == "duration":
        return duration(value)
    if kind == "percent":
        return f"{value:.1f} %"
    return str(int(value))


def change_text(item: Comparison) -> str:
    """The difference with its sign: ``+3``, ``-2m 05s``, ``+1.5 pp``; ``-`` when undefined."""
    change = item.change
    if change is None:
        return "-"
    sign = "+" if change > 0 else "-" if change < 0 else "±"
    size = abs(change)
    if item.kind == "duration":
        return f"{sign}{duration(size)}"
    if item.kind == "percent":
        return f"{sign}{size:.1f} pp"
    return f"{sign}{int(size)}"


def percent_text(item: Comparison) -> str:
    """``+42.9 %``; ``new`` when the previous shift had none; ``-`` when undefined."""
    percent = item.change_percent
    if percent is None:
        return "new" if item.previous == 0 and item.value else "-"
    return f"{percent:+.1f} %"


def local_time(report: ShiftReport, moment: datetime | None) -> str:
    if moment is None:
        return "still CONFIRMED"
    return f"{report.local(moment):%Y-%m-%d %H:%M:%S}"


def group_text(row: StatsRow, key: str) -> str:
    value = row.group.get(key, "")
    return severity_name(value) if key == "severity" and isinstance(value, int) else str(value)


def as_dict(report: ShiftReport) -> dict[str, Any]:
    """The report as JSON for the dashboard (``GET /api/v1/shift-report?format=json``): the
    same figures, previous shift and texts as the terminal and HTML reports."""
    shift, previous = report.shift, report.previous
    return {
        "shift": {"id": shift.id, "name": shift.name, "start": shift.start.isoformat(),
                  "end": shift.end.isoformat(), "span_text": report.span_text,
                  "length_text": report.length_text},
        "timezone": report.timezone,
        "in_progress": report.in_progress,
        "as_of": report.as_of.isoformat(),
        "previous": None if previous is None else {
            "id": previous.id, "start": previous.start.isoformat(),
            "end": previous.end.isoformat()},
        "headline": report.headline,
        "notes": list(report.notes),
        "estop_codes": list(report.estop_codes),
        "figures": [{"key": f.key, "label": f.label, "kind": f.kind, "value": f.value,
                     "previous": f.previous, "value_text": value_text(f.kind, f.value),
                     "previous_text": value_text(f.kind, f.previous),
                     "change_text": change_text(f), "percent_text": percent_text(f)}
                    for f in report.figures],
        "offenders": [{"code": group_text(r, "code"), "estops": r.estops,
                       "activations": r.activations, "confirmations": r.confirmations,
                       "failed_reports": r.failed_reports, "active_seconds": r.active_seconds,
                       "mttr_seconds": r.mttr_seconds} for r in report.offenders],
        "hours": [{"label": h.label, "start": h.start.isoformat(), "estops": h.estops,
                   "activations": h.activations, "confirmations": h.confirmations,
                   "aborted_goals": h.aborted_goals} for h in report.hours],
        "glossary": [{"term": term, "meaning": meaning} for term, meaning in GLOSSARY],
    }
