"""Commands of the operator's day (acknowledge, shelve, unshelve) from the API's arguments:
input checked here, state rules decided by the writer with ``domain.attention``."""

from __future__ import annotations

import math
import time
from datetime import datetime, timedelta

from faultledger.domain import attention
from faultledger.domain.clock import NS_PER_SECOND, in_range, to_ns
from faultledger.domain.events import FaultAcknowledged, FaultShelved, FaultUnshelved
from faultledger.domain.validation import range_message, time_error
from faultledger.service.results import OperatorResult
from faultledger.service.writer import Operate


def _when(at: datetime | None) -> tuple[int, str | None]:
    if at is None:
        return time.time_ns(), None
    problem = time_error("at", at)
    return (0, problem) if problem else (to_ns(at), None)


def _checked(fault_code: str, actor: str, text: str, text_name: str,
             at: datetime | None) -> tuple[int, OperatorResult | None]:
    """The action's time, or the refusal of its input (code, actor, note or reason, at)."""
    problem = attention.input_error(fault_code, actor, text, text_name)
    occurred_ns, time_problem = _when(at)
    problem = problem or time_problem
    return occurred_ns, None if problem is None else OperatorResult(False, problem)


def acknowledge(fault_code: str, actor: str, note: str,
                at: datetime | None) -> Operate | OperatorResult:
    occurred_ns, refused = _checked(fault_code, actor, note, "note", at)
    return refused or Operate(FaultAcknowledged(fault_code, actor, note, 0), occurred_ns)


def shelve(fault_code: str, actor: str, reason: str, duration: str | timedelta | float,
           at: datetime | None) -> Operate | OperatorResult:
    """``duration``: ``2h``/``90m``/``1h30m``, a timedelta or seconds."""
    occurred_ns, refused = _checked(fault_code, actor, reason, "reason", at)
    if refused is not None:
        return refused
    try:
        length = _duration_ns(duration)
    except ValueError as error:
        return OperatorResult(False, f"for: {error}")
    until_ns = occurred_ns + length
    if not in_range(until_ns):
        return OperatorResult(False, range_message("the shelving's end", f"{until_ns} ns"))
    return Operate(FaultShelved(fault_code, actor, reason, until_ns), occurred_ns)


def unshelve(fault_code: str, actor: str, reason: str,
             at: datetime | None) -> Operate | OperatorResult:
    occurred_ns, refused = _checked(fault_code, actor, reason, "reason", at)
    return refused or Operate(FaultUnshelved(fault_code, actor, reason), occurred_ns)


def _duration_ns(duration: str | timedelta | float) -> int:
    if isinstance(duration, str):
        return attention.parse_duration(duration)
    if isinstance(duration, timedelta):
        return attention.checked_duration(round(duration.total_seconds() * NS_PER_SECOND))
    if isinstance(duration, bool) or not isinstance(duration, int | float) or not math.isfinite(
            duration):
        raise ValueError(f"a duration is text (2h), a timedelta or seconds, got {duration!r}")
    return attention.checked_duration(round(duration * NS_PER_SECOND))

