"""Statistics periods (shift, day, hour, 10min) and the range bounds users type."""

from __future__ import annotations

import re
from datetime import UTC, date, datetime, time, timedelta
from zoneinfo import ZoneInfo

from faultledger.domain.clock import TIME_RANGE_TEXT
from faultledger.domain.shifts import Period, ShiftCalendar, ShiftDefinition

PERIOD_KINDS = ("shift", "day", "hour", "10min")
_STEP = {"hour": timedelta(hours=1), "10min": timedelta(minutes=10)}
_DATE = re.compile(r"^\d{4}-\d{2}-\d{2}$")


def default_calendar() -> ShiftCalendar:
    """Three 8-hour shifts in UTC: what `--by shift` means before a site configures its own."""
    return ShiftCalendar(timezone="UTC", shifts=(
        ShiftDefinition(name="morning", start=time(6), end=time(14)),
        ShiftDefinition(name="afternoon", start=time(14), end=time(22)),
        ShiftDefinition(name="night", start=time(22), end=time(6)),
    ))


def periods(by: str, since: datetime, until: datetime, calendar: ShiftCalendar,
            limit: int | None = None) -> list[Period]:
    """[since, until) cut into periods of kind ``by``, each cropped to the range.

    With a ``limit``, at most ``limit + 1`` periods are made: enough for the caller to see
    that the range is too long, without the cost of cutting all of it.
    """
    if by == "shift":
        return calendar.periods(since, until, limit)
    if by == "day":
        return _days(since, until, calendar.zone, limit)
    if by in _STEP:
        return _clock(since, until, calendar.zone, by, limit)
    raise ValueError(f"by must be one of {', '.join(PERIOD_KINDS)}, got {by!r}")


def _full(out: list[Period], limit: int | None) -> bool:
    return limit is not None and len(out) > limit


def _days(since: datetime, until: datetime, zone: ZoneInfo, limit: int | None = None
          ) -> list[Period]:
    out: list[Period] = []
    day = since.astimezone(zone).date()
    while not _full(out, limit):
        start = datetime.combine(day, time(0), tzinfo=zone).astimezone(UTC)
        end = datetime.combine(day + timedelta(days=1), time(0), tzinfo=zone).astimezone(UTC)
        if start >= until:
            return out
        if end > since:
            out.append(Period(day.isoformat(), "day", day, max(start, since), min(end, until)))
        day += timedelta(days=1)
    return out


def _floor(moment: datetime, zone: ZoneInfo, by: str) -> datetime:
    """The local clock boundary at or before ``moment`` (UTC result)."""
    local = moment.astimezone(zone)
    minute = 0 if by == "hour" else local.minute - local.minute % 10
    return local.replace(minute=minute, second=0, microsecond=0).astimezone(UTC)


def _clock(since: datetime, until: datetime, zone: ZoneInfo, by: str,
           limit: int | None = None) -> list[Period]:
    out: list[Period] = []
    start = _floor(since, zone, by)
    while start < until and not _full(out, limit):
        end = _floor(start + _STEP[by], zone, by)
        if end <= start:  # a zone whose offset change is not on the grid
            end = start + _STEP[by]
        local = start.astimezone(zone)
        out.append(Period(local.isoformat(timespec="minutes"), by, local.date(),
                          max(start, since), min(end, until)))
        start = end
    return out


def parse_bound(text: str, calendar: ShiftCalendar, *, upper: bool) -> datetime:
    """A range bound as typed: an ISO date (local midnight), an ISO date-time (local when it
    has no offset) or a shift id (its start; its end when ``upper``)."""
    value = text.strip()
    try:
        if "/" in value:
            instance = calendar.parse_id(value)
            return instance.end if upper else instance.start
        zone = calendar.zone
        if _DATE.match(value):
            return datetime.combine(date.fromisoformat(value), time(0), tzinfo=zone).astimezone(UTC)
        moment = datetime.fromisoformat(value)
        if moment.tzinfo is None:
            moment = moment.replace(tzinfo=zone)
        return moment.astimezone(UTC)
    except OverflowError:  # year 1 or 9999 shifted by the zone's offset
        raise ValueError(f"{text[:40]!r} is outside the times the log can hold "
                         f"({TIME_RANGE_TEXT})") from None
    except ValueError as error:
        if "/" in value:
            raise
        raise ValueError(f"expected a date (2026-11-21), a date-time (2026-11-21T06:00) or a "
                         f"shift id (2026-11-21/night), got {text[:40]!r}") from error
