"""The one time grammar of every adapter (docs/cli.md, "Times"): the CLI's options and the
HTTP API's query parameters parse range bounds and moments here, with the same messages."""

from __future__ import annotations

import re
from datetime import datetime

from faultledger.domain import validation
from faultledger.domain.periods import parse_bound
from faultledger.domain.shifts import ShiftCalendar
from faultledger.errors import InvalidInputError

SEQ_NUMBER = re.compile(r"[0-9]{1,19}")
"""A seq number where a time or a seq may be given (ASCII digits that fit 64 bits)."""
EXPECTED_TIME = "an ISO 8601 date or time, or a shift id"
EXAMPLES = "(e.g. 2026-11-21, 2026-11-21T22:00, 2026-11-21T22:00Z or 2026-11-21/night)"


def parse_time(text: str | None, name: str, calendar: ShiftCalendar, *,
               upper: bool = False, expected: str = EXPECTED_TIME) -> datetime | None:
    """A shift id (its start; its end when ``upper``), an ISO date (local midnight in the
    calendar's zone) or an ISO date-time (in the calendar's zone when naive; an explicit
    offset or Z is honoured). The result is timezone-aware and within the times the log can
    hold; anything else is an ``InvalidInputError`` naming ``name``."""
    if text is None:
        return None
    value = text.strip()
    try:
        moment = parse_bound(value, calendar, upper=upper)
    except ValueError as error:
        if "outside the times" in str(error):
            raise InvalidInputError(
                validation.range_message(name, validation.shown(text))) from None
        if "/" in value:
            raise InvalidInputError(f"{name}: {error}") from None
        raise InvalidInputError(f"{name} must be {expected} {EXAMPLES}, got "
                                f"{validation.shown(text)}") from None
    problem = validation.time_error(name, moment)
    if problem:
        raise InvalidInputError(problem)
    return moment


def parse_moment(text: str, name: str, calendar: ShiftCalendar) -> datetime | int:
    """A seq number (ASCII digits) or a time (``parse_time``): `list --at`, `state-at`."""
    if SEQ_NUMBER.fullmatch(text.strip()):
        return int(text.strip())
    moment = parse_time(text, name, calendar,
                        expected="a seq number or an ISO 8601 date or time, or a shift id")
    assert moment is not None
    return moment
