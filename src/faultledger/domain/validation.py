"""Input rules of SPEC §4.5: one function per entry, returning the exact message or None."""

from __future__ import annotations

import math
import re
import unicodedata
from datetime import datetime

from faultledger.domain.clock import MAX_NS, MIN_NS, TIME_RANGE_TEXT, in_range, to_ns
from faultledger.domain.events import GOAL_STATUSES
from faultledger.domain.types import EVENT_TYPES_BY_NAME, EventType

MAX_FAULT_CODE_LENGTH = 128
MAX_DESCRIPTION_LENGTH = 4096
MAX_SOURCE_ID_LENGTH = 1024
MAX_ACTOR_LENGTH = 256
MIN_INTEGER, MAX_INTEGER = -(2**63), 2**63 - 1
"""What an integer field may hold: a signed 64-bit column in every database we support."""

_INVALID_CHAR = re.compile(r"[^A-Za-z0-9_.\-]")
MAX_ROBOT_ID_LENGTH = 128
ROBOT_ID_RULE = (f"1..{MAX_ROBOT_ID_LENGTH} characters: ASCII letters, digits, _ . -, starting "
                 "with a letter or digit")
_ROBOT_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]*")


def shown(value: object, limit: int = 60) -> str:
    """A value quoted in a message: its repr (control characters escaped), clipped, so a huge
    or hostile input never makes a huge or multi-line message."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}…(+{len(text) - limit} chars)"


def fault_code_error(fault_code: str) -> str | None:
    if not isinstance(fault_code, str):
        return f"fault_code must be a string, got {type(fault_code).__name__}"
    if not fault_code:
        return "fault_code cannot be empty"
    if len(fault_code) > MAX_FAULT_CODE_LENGTH:
        return f"fault_code exceeds maximum length of {MAX_FAULT_CODE_LENGTH}"
    bad = _INVALID_CHAR.search(fault_code)
    if bad is not None:
        char = bad.group()
        if not char.isprintable():  # quoted as an escape, never as the raw control character
            char = repr(char)[1:-1]
        return (
            f"fault_code contains invalid character '{char}'. "
            "Only alphanumeric, underscore, hyphen, and dot are allowed"
        )
    if ".." in fault_code:
        return "fault_code cannot contain '..'"
    return None


def parse_event_type(event_type: object) -> EventType | None:
    """Accept EventType, 0/1 or the names FAILED/PASSED (any case); None when it is neither."""
    if isinstance(event_type, bool):
        return None
    if isinstance(event_type, int):
        return EventType(event_type) if event_type in (0, 1) else None
    if isinstance(event_type, str):  # the exact spelling first: nearly every report uses it
        exact = EVENT_TYPES_BY_NAME.get(event_type)
        return exact if exact is not None else EVENT_TYPES_BY_NAME.get(event_type.strip().upper())
    return None


def text_error(name: str, value: str, limit: int) -> str | None:
    """Type, length bound, UTF-8 encodability (lone surrogates come from undecodable argv
    bytes) and no NUL: a NUL cannot travel faithfully through ROS strings or C tools (they
    end the text there), so it is refused rather than stored as something else later shows
    truncated. Other control characters are stored as given and shown escaped."""
    if not isinstance(value, str):
        return f"{name} must be a string, got {type(value).__name__}"
    if len(value) > limit:
        return f"{name} exceeds maximum length of {limit} (got {len(value)})"
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        return f"{name} is not valid UTF-8 text"
    nul = value.find("\x00")
    if nul >= 0:
        return f"{name} contains a NUL character (\\x00) at position {nul}"
    return None


def severity_error(severity: object) -> str | None:
    """0..3 on FAILED and on PASSED alike. medkit checks it on FAILED only, but a PASSED's
    severity is stored too (and counted by the statistics' severity groups), so a value off
    the scale (255 from a uint8 field) is refused with the same message."""
    if isinstance(severity, int) and not isinstance(severity, bool) and 0 <= severity <= 3:
        return None
    return f"severity must be 0 (INFO) to 3 (CRITICAL), got {shown(severity)}"


def time_error(name: str, moment: object) -> str | None:
    """A time the log can hold: timezone-aware, within MIN_NS..MAX_NS."""
    if not isinstance(moment, datetime):
        return f"{name} must be a timezone-aware datetime, got {type(moment).__name__}"
    try:
        ns = to_ns(moment)
    except (ValueError, OverflowError):
        return f"{name} must be a timezone-aware datetime (with a UTC offset), got {moment!r}"
    return None if in_range(ns) else range_message(name, moment.isoformat())


def ns_error(name: str, value: object) -> str | None:
    """A time given as integer nanoseconds since the epoch."""
    if isinstance(value, bool) or not isinstance(value, int):
        return (f"{name} must be a timezone-aware datetime or nanoseconds since the epoch, got "
                f"{shown(value)}")
    return None if MIN_NS <= value <= MAX_NS else range_message(name, f"{value} ns")


def range_message(name: str, given: str) -> str:
    return f"{name} {given} is outside the times the log can hold ({TIME_RANGE_TEXT})"


def finite_error(name: str, value: object) -> str | None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return f"{name} must be a finite number, got {shown(value)}"
    return None


def report_error(
    fault_code: str, event_type: object, severity: object, description: str, source_id: str
) -> str | None:
    """First problem with a report, in medkit's order: code, type, severity, source; else None."""
    problem = fault_code_error(fault_code)
    if problem:
        return problem
    kind = parse_event_type(event_type)
    if kind is None:
        return f"event_type must be FAILED (0) or PASSED (1), got {shown(event_type)}"
    problem = severity_error(severity)
    if problem:
        return problem
    if isinstance(source_id, str) and not source_id:
        return "source_id cannot be empty"
    return text_error("source_id", source_id, MAX_SOURCE_ID_LENGTH) or text_error(
        "description", description, MAX_DESCRIPTION_LENGTH
    )


def clear_error(fault_code: str, actor: str, reason: str) -> str | None:
    return (
        fault_code_error(fault_code)
        or text_error("actor", actor, MAX_ACTOR_LENGTH)
        or text_error("reason", reason, MAX_DESCRIPTION_LENGTH)
    )


def entity_error(entity_id: str) -> str | None:
    if isinstance(entity_id, str) and not entity_id:
        return "entity_id cannot be empty"
    return text_error("entity_id", entity_id, MAX_SOURCE_ID_LENGTH)


MAX_ACTION_LENGTH = 256
MAX_GOAL_ID_LENGTH = 64
MAX_SERVER_NODE_LENGTH = 256


def _control_error(name: str, value: str) -> str | None:
    """A name (ROS action, goal id) holds no control character: shown escaped, with where."""
    for position, char in enumerate(value):
        if unicodedata.category(char) == "Cc":
            return (f"{name} contains a control character ({repr(char)[1:-1]}) at position "
                    f"{position}")
    return None


def goal_outcome_error(action: object, goal_id: object, status: object,
                       server_node: object) -> str | None:
    """First problem with a goal outcome (action, goal id, status, server node); else None."""
    for name, value, limit in (("action", action, MAX_ACTION_LENGTH),
                               ("goal_id", goal_id, MAX_GOAL_ID_LENGTH)):
        if isinstance(value, str) and not value:
            return f"{name} cannot be empty"
        problem = text_error(name, value, limit)  # type: ignore[arg-type]
        if problem:
            return problem
        problem = _control_error(name, value)  # type: ignore[arg-type]
        if problem:
            return problem
    if not isinstance(status, str) or status not in GOAL_STATUSES:
        return f"status must be SUCCEEDED, ABORTED or CANCELED, got {shown(status)}"
    return text_error("server_node", server_node, MAX_SERVER_NODE_LENGTH)  # type: ignore[arg-type]


def robot_id_error(robot_id: object) -> str | None:
    """A robot_id names the robot in URLs, file names and a central's tokens: plain ASCII."""
    if not isinstance(robot_id, str):
        return f"robot_id must be a string, got {type(robot_id).__name__}"
    if (not 0 < len(robot_id) <= MAX_ROBOT_ID_LENGTH
            or _ROBOT_ID.fullmatch(robot_id) is None):
        return f"robot_id must be {ROBOT_ID_RULE}; got {shown(robot_id)}"
    return None
