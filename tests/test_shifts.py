"""Shift calendars (issue 5): local-time shifts in an IANA zone, DST, weekdays, gaps, versions."""

from __future__ import annotations

import itertools
from datetime import UTC, date, datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pydantic import ValidationError

from faultledger.domain.shifts import UNSCHEDULED, ShiftCalendar
from faultledger.errors import ConfigError
from faultledger.service.config import load_shift_calendar

THREE_SHIFTS = [
    {"name": "morning", "start": "06:00", "end": "14:00"},
    {"name": "afternoon", "start": "14:00", "end": "22:00"},
    {"name": "night", "start": "22:00", "end": "06:00"},
]


def calendar(zone: str = "Europe/Berlin", shifts: list[dict[str, Any]] | None = None,
             versions: list[dict[str, Any]] | None = None) -> ShiftCalendar:
    return ShiftCalendar.model_validate({"timezone": zone, "shifts": shifts or THREE_SHIFTS,
                                         "versions": versions or []})


def utc(year: int, month: int, day: int, hour: int = 0) -> datetime:
    return datetime(year, month, day, hour, tzinfo=UTC)


def hours(zone: str, shift_id: str) -> float:
    return calendar(zone).parse_id(shift_id).seconds / 3600


@pytest.mark.parametrize(("zone", "shift_id", "expected"), [
    ("Europe/Berlin", "2026-03-28/night", 7.0),     # spring forward, 29 March 02:00 → 03:00
    ("Europe/Berlin", "2026-10-24/night", 9.0),     # fall back, 25 October 03:00 → 02:00
    ("Europe/Berlin", "2026-03-27/night", 8.0),
    ("Europe/Berlin", "2026-03-29/morning", 8.0),
    ("America/Chicago", "2026-03-07/night", 7.0),   # 8 March 2026
    ("America/Chicago", "2026-10-31/night", 9.0),   # 1 November 2026
    ("America/Chicago", "2026-11-01/night", 8.0),
])
def test_night_shift_length_follows_dst(zone: str, shift_id: str, expected: float) -> None:
    assert hours(zone, shift_id) == expected


def test_instance_times_are_local_wall_clock_converted_to_utc() -> None:
    night = calendar().parse_id("2026-11-21/night")
    assert (night.id, night.name, night.production_day) == ("2026-11-21/night", "night",
                                                           date(2026, 11, 21))
    assert (night.start, night.end) == (utc(2026, 11, 21, 21), utc(2026, 11, 22, 5))
    chicago = calendar("America/Chicago").parse_id("2026-07-01/morning")
    assert (chicago.start, chicago.end) == (utc(2026, 7, 1, 11), utc(2026, 7, 1, 19))


def test_boundaries_start_inclusive_end_exclusive() -> None:
    cal = calendar()
    night = cal.parse_id("2026-11-21/night")
    assert cal.shift_at(night.start) == night
    assert cal.shift_at(night.end - timedelta(microseconds=1)) == night
    following = cal.shift_at(night.end)
    assert following is not None and following.id == "2026-11-22/morning"


def test_an_overnight_moment_belongs_to_the_shift_of_the_previous_production_day() -> None:
    at = calendar().shift_at(utc(2026, 11, 22, 2))  # 03:00 local on the 22nd
    assert at is not None
    assert at.id == "2026-11-21/night"


def test_weekday_only_shifts_leave_weekends_unscheduled() -> None:
    cal = calendar(shifts=[{"name": "day", "start": "08:00", "end": "16:00",
                            "weekdays": ["mon", "tue", "wed", "thu", "fri"]}])
    # Friday 20 Nov 2026 .. Monday 23 Nov 2026 (local = UTC+1)
    periods = cal.periods(utc(2026, 11, 20, 0), utc(2026, 11, 23, 12))
    assert [(p.id, p.start, p.end) for p in periods] == [
        (UNSCHEDULED, utc(2026, 11, 20, 0), utc(2026, 11, 20, 7)),
        ("2026-11-20/day", utc(2026, 11, 20, 7), utc(2026, 11, 20, 15)),
        (UNSCHEDULED, utc(2026, 11, 20, 15), utc(2026, 11, 23, 7)),
        ("2026-11-23/day", utc(2026, 11, 23, 7), utc(2026, 11, 23, 12)),
    ]
    assert cal.shift_at(utc(2026, 11, 21, 10)) is None
    with pytest.raises(ValueError, match=r"no shift 'day' starts on 2026-11-21 \(shifts that "
                                         r"day: none\)"):
        cal.parse_id("2026-11-21/day")


def test_calendar_change_applies_from_its_effective_production_day_only() -> None:
    cal = calendar(versions=[{"effective": "2026-11-16", "shifts": [
        {"name": "early", "start": "05:00", "end": "13:00"},
        {"name": "late", "start": "13:00", "end": "21:00"},
    ]}])
    # The night of the 15th (old calendar) runs into the 16th and keeps its old definition.
    old_night = cal.parse_id("2026-11-15/night")
    assert (old_night.start, old_night.end) == (utc(2026, 11, 15, 21), utc(2026, 11, 16, 5))
    periods = cal.periods(utc(2026, 11, 15, 20), utc(2026, 11, 16, 22))
    # 'early' starts 05:00 local (04:00 UTC), while the old night runs until 05:00 UTC: at the
    # change the earlier shift keeps its hour and 'early' is counted from when it ends.
    assert [(p.id, p.start, p.end) for p in periods] == [
        ("2026-11-15/afternoon", utc(2026, 11, 15, 20), utc(2026, 11, 15, 21)),
        ("2026-11-15/night", utc(2026, 11, 15, 21), utc(2026, 11, 16, 5)),
        ("2026-11-16/early", utc(2026, 11, 16, 5), utc(2026, 11, 16, 12)),
        ("2026-11-16/late", utc(2026, 11, 16, 12), utc(2026, 11, 16, 20)),
        (UNSCHEDULED, utc(2026, 11, 16, 20), utc(2026, 11, 16, 22)),
    ]
    assert cal.parse_id("2026-11-01/night").name == "night"
    with pytest.raises(ValueError, match="no shift 'night' starts on 2026-11-20"):
        cal.parse_id("2026-11-20/night")


def test_previous_instance_of_the_same_shift() -> None:
    cal = calendar()
    prev = cal.previous(cal.parse_id("2026-11-21/night"))
    assert prev is not None and prev.id == "2026-11-20/night"


@pytest.mark.parametrize(("zone", "shift_id"), [
    *((zone, shift_id) for zone in ("Europe/Berlin", "Pacific/Kiritimati", "Etc/GMT+12")
      for shift_id in ("9999-12-31/night", "9999-12-31/morning", "0001-01-01/night")),
    ("Europe/Berlin", "1969-12-31/night"), ("Europe/Berlin", "2262-04-11/night"),
    ("Etc/GMT-12", "1970-01-01/morning"), ("Etc/GMT+12", "2262-04-11/afternoon")])
def test_a_shift_outside_the_times_the_log_can_hold_is_refused(zone: str,
                                                               shift_id: str) -> None:
    """Issue 18: year 9999's night ended past what a datetime holds (OverflowError); in UTC
    a shift must lie within 1970 .. 2262-04-11T23:47:16Z, whatever its zone."""
    with pytest.raises(ValueError, match=f"^shift {shift_id} is outside the times the log can "
                       r"hold \(1970-01-01T00:00:00Z \.\. 2262-04-11T23:47:16Z\)$"):
        calendar(zone).parse_id(shift_id)


def test_the_first_shift_of_1970_has_no_previous_instance() -> None:
    cal = calendar("UTC")
    assert cal.previous(cal.parse_id("1970-01-01/morning")) is None
    assert cal.previous(cal.parse_id("1970-01-02/morning")) is not None


@pytest.mark.parametrize(("data", "message"), [
    ({"timezone": "Mars/Olympus", "shifts": THREE_SHIFTS}, "unknown IANA time zone"),
    ({"timezone": "UTC", "shifts": [{"name": "a", "start": "06:00", "end": "15:00"},
                                    {"name": "b", "start": "14:00", "end": "22:00"}]},
     "shifts 'a' and 'b' overlap"),
    ({"timezone": "UTC", "shifts": [{"name": "a", "start": "22:00", "end": "07:00"},
                                    {"name": "b", "start": "06:00", "end": "14:00"}]},
     "shifts 'a' and 'b' overlap"),
    ({"timezone": "UTC", "shifts": [{"name": "a", "start": "06:00", "end": "14:00"},
                                    {"name": "a", "start": "14:00", "end": "22:00"}]},
     "shift names must be unique"),
    ({"timezone": "UTC", "shifts": [{"name": "unscheduled", "start": "06:00",
                                     "end": "14:00"}]}, "reserved"),
    ({"timezone": "UTC", "shifts": [{"name": "Night Shift", "start": "06:00",
                                     "end": "14:00"}]}, "should match pattern"),
    ({"timezone": "UTC", "shifts": [{"name": "a", "start": "06:00", "end": "14:00",
                                     "weekdays": ["monday"]}]}, "Input should be 'mon'"),
    ({"timezone": "UTC", "shifts": THREE_SHIFTS,
      "versions": [{"effective": "2027-01-01", "shifts": THREE_SHIFTS},
                   {"effective": "2026-01-01", "shifts": THREE_SHIFTS}]}, "ascending order"),
])
def test_invalid_calendars_are_refused_with_the_reason(data: dict[str, Any],
                                                       message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        ShiftCalendar.model_validate(data)


def test_shipped_calendar_loads_and_bad_files_name_the_field(tmp_path: Path) -> None:
    shipped = load_shift_calendar(Path(__file__).parent.parent / "config" / "shifts.yaml")
    assert [s.name for s in shipped.shifts] == ["morning", "afternoon", "night"]
    bad = tmp_path / "shifts.yaml"
    bad.write_text("timezone: Europe/Berlin\nshifts: []\n")
    with pytest.raises(ConfigError, match=f"shift calendar {bad} is invalid: shifts: "):
        load_shift_calendar(bad)


@given(start=st.integers(0, 400 * 24), length=st.integers(1, 10 * 24),
       zone=st.sampled_from(["Europe/Berlin", "America/Chicago", "UTC"]))
def test_periods_partition_the_range_and_agree_with_shift_at(start: int, length: int,
                                                             zone: str) -> None:
    cal = calendar(zone, shifts=[*THREE_SHIFTS[:2],
                                 {"name": "night", "start": "22:00", "end": "05:30",
                                  "weekdays": ["mon", "tue", "wed", "thu", "fri"]}])
    since = utc(2026, 1, 1) + timedelta(hours=start)
    until = since + timedelta(hours=length)
    periods = cal.periods(since, until)
    assert periods[0].start == since and periods[-1].end == until
    for before, after in itertools.pairwise(periods):
        assert before.end == after.start and before.start < before.end
    for period in periods:
        middle = period.start + (period.end - period.start) / 2
        inst = cal.shift_at(middle)
        assert (inst.id if inst else UNSCHEDULED) == period.id
