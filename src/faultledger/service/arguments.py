"""Checks of the arguments the read API takes (filters, seqs, limits, times): bad input is an
InvalidInputError naming it, never a silently empty or wrong answer."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from datetime import datetime

from faultledger.domain import validation
from faultledger.domain.clock import to_ns
from faultledger.domain.events import KINDS
from faultledger.errors import InvalidInputError
from faultledger.service import statistics
from faultledger.store import event_log


def record_filter(code: str | None, since: datetime | int | None, until: datetime | int | None,
                  source: str | None, kinds: Iterable[str], limit: int | None,
                  codes: Sequence[str] | None, from_seq: int | None, to_seq: int | None
                  ) -> event_log.RecordFilter:
    """A checked history filter: bad input is an InvalidInputError naming it, never a silently
    empty answer (a misspelt kind would otherwise look like "nothing happened")."""
    wanted = strings(kinds, "kinds")
    unknown = [kind for kind in wanted if kind not in KINDS]
    if unknown:
        named = ", ".join(validation.shown(kind, 40) for kind in unknown[:5])
        raise InvalidInputError(f"unknown record kind {named}; valid "
                                f"kinds: {', '.join(KINDS)}")
    patterns = strings(codes, "codes")
    if len(patterns) > statistics.MAX_PATTERNS:
        raise InvalidInputError(f"codes takes at most {statistics.MAX_PATTERNS} patterns")
    for name, value, size in (*(("a code pattern", c, statistics.MAX_PATTERN_LENGTH)
                                for c in patterns),
                              ("code", code, validation.MAX_FAULT_CODE_LENGTH),
                              ("source", source, validation.MAX_SOURCE_ID_LENGTH)):
        problem = None if value is None else validation.text_error(name, value, size)
        if problem:
            raise InvalidInputError(problem)
    check_seq_range(from_seq, to_seq)
    check_limit(limit)
    return event_log.RecordFilter(
        fault_code=code, source_id=source, since_ns=bound_ns(since, "since"),
        until_ns=bound_ns(until, "until"), kinds=wanted, limit=limit, codes=patterns,
        from_seq=from_seq, to_seq=to_seq,
    )


def strings(value: Iterable[str] | str | None, name: str) -> tuple[str, ...]:
    """One string or a collection of them as a tuple; anything else is refused by name."""
    if value is None:
        return ()
    if isinstance(value, str):
        return (value,)
    if not isinstance(value, list | tuple | set | frozenset) or len(value) > 10_000 or not all(
            isinstance(item, str) for item in value):
        raise InvalidInputError(f"{name} must be a list of strings, got "
                                f"{validation.shown(value)}")
    return tuple(value)


def check_limit(limit: int | None) -> None:
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int)
                              or not 0 <= limit <= validation.MAX_INTEGER):
        raise InvalidInputError(f"limit must be a whole number of 0 or more, got "
                                f"{validation.shown(limit)}")


def seq_number(value: int, name: str) -> int:
    """``value`` when it can be a seq (0 names the empty prefix)."""
    if (isinstance(value, bool) or not isinstance(value, int)
            or not 0 <= value <= validation.MAX_INTEGER):
        raise InvalidInputError(f"{name} must be a seq number of 0 or more, got "
                                f"{validation.shown(value)}")
    return value


def check_seq_range(from_seq: int | None, to_seq: int | None) -> None:
    for name, value in (("from_seq", from_seq), ("to_seq", to_seq)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or not 1 <= value <= validation.MAX_INTEGER):
            raise InvalidInputError(f"{name} must be a seq number of 1 or more, got {value!r}")
    if from_seq is not None and to_seq is not None and from_seq > to_seq:
        raise InvalidInputError(f"from_seq {from_seq} is after to_seq {to_seq}: the range is "
                                "empty")


def bound_ns(moment: datetime | int | None, name: str) -> int | None:
    if moment is None:
        return None
    if isinstance(moment, datetime):
        return aware_ns(moment, name)
    problem = validation.ns_error(name, moment)
    if problem:
        raise InvalidInputError(problem)
    return moment


def aware_ns(moment: datetime, name: str) -> int:
    """A datetime argument as nanoseconds; InvalidInputError unless the log can hold it."""
    problem = validation.time_error(name, moment)
    if problem:
        raise InvalidInputError(problem)
    return to_ns(moment)
