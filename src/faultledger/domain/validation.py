"""Input rules of SPEC §4.5: one function per entry, returning the exact message or None."""

from __future__ import annotations

import re

from faultledger.domain.types import EventType

MAX_FAULT_CODE_LENGTH = 128
MAX_DESCRIPTION_LENGTH = 4096
MAX_SOURCE_ID_LENGTH = 1024
MAX_ACTOR_LENGTH = 256

_INVALID_CHAR = re.compile(r"[^A-Za-z0-9_.\-]")


def fault_code_error(fault_code: str) -> str | None:
    if not fault_code:
        return "fault_code cannot be empty"
    if len(fault_code) > MAX_FAULT_CODE_LENGTH:
        return f"fault_code exceeds maximum length of {MAX_FAULT_CODE_LENGTH}"
    bad = _INVALID_CHAR.search(fault_code)
    if bad is not None:
        return (
            f"fault_code contains invalid character '{bad.group()}'. "
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
    if isinstance(event_type, str):
        return EventType.__members__.get(event_type.strip().upper())
    return None


def text_error(name: str, value: str, limit: int) -> str | None:
    """Length bound and UTF-8 encodability (lone surrogates come from undecodable argv bytes)."""
    if len(value) > limit:
        return f"{name} exceeds maximum length of {limit} (got {len(value)})"
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        return f"{name} is not valid UTF-8 text"
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
        return f"event_type must be FAILED (0) or PASSED (1), got {event_type!r}"
    if kind is EventType.FAILED and (
        isinstance(severity, bool) or not isinstance(severity, int) or not 0 <= severity <= 3
    ):
        return f"severity must be 0 (INFO) to 3 (CRITICAL), got {severity!r}"
    if not source_id:
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
    if not entity_id:
        return "entity_id cannot be empty"
    return text_error("entity_id", entity_id, MAX_SOURCE_ID_LENGTH)
