"""Shift calendars: which shift instance (or `unscheduled`) a moment belongs to.

Shifts are defined in local wall-clock time of one IANA zone and converted with zoneinfo, so a
22:00-06:00 shift lasts 7 h on the spring-forward night and 9 h on the fall-back night (in
Europe/Berlin). A calendar may change: each version applies to the shift instances whose
production day (the local day the shift starts on) is on or after its effective date, so a
new calendar never moves reports of earlier periods into other shifts.
"""

from __future__ import annotations

import itertools
import re
from datetime import UTC, date, datetime, time, timedelta
from typing import Literal, NamedTuple
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from faultledger.domain.clock import MAX_TIME, MIN_TIME, TIME_RANGE_TEXT

Weekday = Literal["mon", "tue", "wed", "thu", "fri", "sat", "sun"]
WEEKDAYS: tuple[Weekday, ...] = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")
UNSCHEDULED = "unscheduled"
_SHIFT_ID = re.compile(r"^(\d{4}-\d{2}-\d{2})/([a-z0-9_-]+)$")


class ShiftDefinition(BaseModel):
    """One named shift in local time; ``end <= start`` means it ends the next day."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field(pattern=r"^[a-z0-9_-]+$", max_length=32)
    start: time
    end: time
    weekdays: tuple[Weekday, ...] = WEEKDAYS
    """Days the shift *starts* on; all days when omitted."""

    @field_validator("name")
    @classmethod
    def _not_reserved(cls, name: str) -> str:
        if name == UNSCHEDULED:
            raise ValueError(f"'{UNSCHEDULED}' is reserved for time outside every shift")
        return name

    @property
    def overnight(self) -> bool:
        return self.end <= self.start


class CalendarVersion(BaseModel):
    """The shifts in force for production days from ``effective`` on."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    effective: date
    shifts: tuple[ShiftDefinition, ...] = Field(min_length=1)

    @model_validator(mode="after")
    def _no_overlap(self) -> CalendarVersion:
        _check_week(self.shifts, f"calendar version effective {self.effective}")
        return self


class ShiftCalendar(BaseModel):
    """``config/shifts.yaml``: a zone, the shifts, and optional later versions."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    timezone: str
    shifts: tuple[ShiftDefinition, ...] = Field(min_length=1)
    versions: tuple[CalendarVersion, ...] = ()
    """Changes of the calendar; ``shifts`` applies before the first of them."""

    @field_validator("timezone")
    @classmethod
    def _known_zone(cls, name: str) -> str:
        try:
            ZoneInfo(name)
        except (ZoneInfoNotFoundError, ValueError):
            raise ValueError(f"unknown IANA time zone {name!r}") from None
        return name

    @model_validator(mode="after")
    def _ordered_and_disjoint(self) -> ShiftCalendar:
        _check_week(self.shifts, "shifts")
        dates = [v.effective for v in self.versions]
        if dates != sorted(set(dates)):
            raise ValueError("versions must have distinct effective dates in ascending order")
        return self

    @property
    def zone(self) -> ZoneInfo:
        return ZoneInfo(self.timezone)

    def summary(self, day: date | None = None) -> str:
        """One line for start-up messages: ``Europe/Berlin: morning 06:00-14:00, afternoon
        14:00-22:00, night 22:00-06:00`` (the version in force on ``day``, default the
        first)."""
        shifts = self.shifts if day is None else self.shifts_on(day) or self.shifts
        parts = [f"{s.name} {s.start:%H:%M}-{s.end:%H:%M}"
                 + ("" if s.weekdays == WEEKDAYS else f" ({','.join(s.weekdays)})")
                 for s in shifts]
        return f"{self.timezone}: {', '.join(parts)}"

    def shifts_on(self, day: date) -> tuple[ShiftDefinition, ...]:
        """Shifts starting on production day ``day`` under the version in force then."""
        shifts = self.shifts
        for version in self.versions:
            if version.effective <= day:
                shifts = version.shifts
        weekday = WEEKDAYS[day.weekday()]
        return tuple(s for s in shifts if weekday in s.weekdays)

    def instance(self, day: date, shift: ShiftDefinition) -> ShiftInstance:
        zone = self.zone
        start = datetime.combine(day, shift.start, tzinfo=zone)
        end_day = day + timedelta(days=1) if shift.overnight else day
        end = datetime.combine(end_day, shift.end, tzinfo=zone)
        return ShiftInstance(f"{day.isoformat()}/{shift.name}", shift.name, day,
                             start.astimezone(UTC), end.astimezone(UTC))

    def instances(self, since: datetime, until: datetime) -> list[ShiftInstance]:
        """Shift instances overlapping [since, until), in time order."""
        zone = self.zone
        first = since.astimezone(zone).date() - timedelta(days=1)
        last = until.astimezone(zone).date()
        found: list[ShiftInstance] = []
        day = first
        while day <= last:
            for shift in self.shifts_on(day):
                inst = self.instance(day, shift)
                if inst.end > since and inst.start < until and inst.end > inst.start:
                    found.append(inst)
            day += timedelta(days=1)
        return sorted(found, key=lambda i: i.start)

    def periods(self, since: datetime, until: datetime, limit: int | None = None
                ) -> list[Period]:
        """[since, until) cut into shift instances and the unscheduled gaps between them,
        each cropped to the range; with a ``limit``, stops after ``limit + 1`` periods."""
        out: list[Period] = []
        cursor = since
        for inst in self.instances(since, until):
            if limit is not None and len(out) > limit:
                return out
            start, end = max(inst.start, since), min(inst.end, until)
            if start > cursor:
                out.append(Period(UNSCHEDULED, UNSCHEDULED, None, cursor, start))
            if end > max(start, cursor):
                out.append(Period(inst.id, inst.name, inst.production_day, max(start, cursor),
                                  end))
                cursor = end
        if cursor < until:
            out.append(Period(UNSCHEDULED, UNSCHEDULED, None, cursor, until))
        return out

    def shift_at(self, moment: datetime) -> ShiftInstance | None:
        """The instance containing ``moment`` (start inclusive, end exclusive), if any."""
        for inst in self.instances(moment, moment + timedelta(microseconds=1)):
            if inst.start <= moment < inst.end:
                return inst
        return None

    def parse_id(self, shift_id: str) -> ShiftInstance:
        """``2026-11-21/night`` → that instance; a clear error if there is none."""
        match = _SHIFT_ID.match(shift_id)
        if match is None:
            raise ValueError(f"shift id must look like 2026-11-21/night, got {shift_id!r}")
        day = date.fromisoformat(match.group(1))
        for shift in self.shifts_on(day):
            if shift.name == match.group(2):
                try:
                    found = self.instance(day, shift)
                except OverflowError:  # ends after 9999-12-31, or starts before year 1 in UTC
                    found = None
                if found is None or found.start < MIN_TIME or found.end > MAX_TIME:
                    raise ValueError(f"shift {shift_id} is outside the times the log can hold "
                                     f"({TIME_RANGE_TEXT})")
                return found
        names = ", ".join(s.name for s in self.shifts_on(day)) or "none"
        raise ValueError(f"no shift {match.group(2)!r} starts on {day} "
                         f"(shifts that day: {names})")

    def previous(self, inst: ShiftInstance, search_days: int = 28) -> ShiftInstance | None:
        """The previous instance of the same shift name (for comparisons)."""
        for back in range(1, search_days + 1):
            day = inst.production_day - timedelta(days=back)
            for shift in self.shifts_on(day):
                if shift.name == inst.name:
                    found = self.instance(day, shift)
                    return found if found.start >= MIN_TIME else None  # none before 1970
        return None


class ShiftInstance(NamedTuple):
    id: str
    name: str
    production_day: date
    start: datetime
    end: datetime

    @property
    def seconds(self) -> float:
        return (self.end - self.start).total_seconds()


class Period(NamedTuple):
    """A stretch of time for statistics: a (cropped) shift instance or an unscheduled gap."""

    id: str
    name: str
    production_day: date | None
    start: datetime
    end: datetime


def _check_week(shifts: tuple[ShiftDefinition, ...], where: str) -> None:
    """Reject shifts that overlap in local time over a generic week (ignoring DST)."""
    names = [s.name for s in shifts]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise ValueError(f"{where}: shift names must be unique, repeated: {duplicates}")
    week = 7 * 24 * 60
    spans: list[tuple[int, int, str]] = []
    for shift in shifts:
        for weekday in shift.weekdays:
            begin = WEEKDAYS.index(weekday) * 1440 + shift.start.hour * 60 + shift.start.minute
            length = (shift.end.hour * 60 + shift.end.minute) - (
                shift.start.hour * 60 + shift.start.minute)
            if length <= 0:
                length += 1440
            spans.append((begin, begin + length, shift.name))
    # Unroll one extra week so a Sunday night shift meets Monday morning.
    unrolled = sorted(spans + [(b + week, e + week, n) for b, e, n in spans])
    for (_, end, name), (begin, _, other) in itertools.pairwise(unrolled):
        if begin < end:
            raise ValueError(f"{where}: shifts {name!r} and {other!r} overlap")
