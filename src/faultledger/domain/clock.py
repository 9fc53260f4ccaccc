"""Conversions between timezone-aware datetimes and the integer nanoseconds stored in the log."""

from __future__ import annotations

from datetime import UTC, datetime

NS_PER_SECOND = 1_000_000_000
_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)

MIN_NS = 0
"""Earliest time the log holds: the Unix epoch (a robot whose clock was never set reports
1970, never earlier)."""
MAX_NS = 2**63 - 1
"""Latest time the log holds: nanoseconds in a signed 64-bit integer (2262-04-11T23:47:16Z),
what SQLite and PostgreSQL store in an INTEGER/BIGINT column."""
MIN_TIME = _EPOCH
MAX_TIME = datetime(2262, 4, 11, 23, 47, 16, 854775, tzinfo=UTC)
TIME_RANGE_TEXT = "1970-01-01T00:00:00Z .. 2262-04-11T23:47:16Z"


def to_ns(moment: datetime) -> int:
    """Nanoseconds since the Unix epoch; naive datetimes are refused so no local time sneaks in."""
    if moment.tzinfo is None or moment.tzinfo.utcoffset(moment) is None:
        raise ValueError("time must be a timezone-aware datetime")
    delta = moment - _EPOCH
    return (delta.days * 86_400 + delta.seconds) * NS_PER_SECOND + delta.microseconds * 1_000


def in_range(ns: int) -> bool:
    """Whether the log can hold this time (see MIN_NS, MAX_NS)."""
    return MIN_NS <= ns <= MAX_NS


def from_ns(ns: int) -> datetime:
    seconds, rest = divmod(ns, NS_PER_SECOND)
    return datetime.fromtimestamp(seconds, tz=UTC).replace(microsecond=rest // 1_000)


def iso_ns(ns: int) -> str:
    """ISO 8601 UTC with all nine digits of the nanoseconds (exports, anchors): a datetime
    would keep only microseconds."""
    seconds, rest = divmod(ns, NS_PER_SECOND)
    return (datetime.fromtimestamp(seconds, tz=UTC).strftime("%Y-%m-%dT%H:%M:%S")
            + f".{rest:09d}+00:00")
