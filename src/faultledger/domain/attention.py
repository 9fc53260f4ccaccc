"""The operator's rules (docs/semantics.md, "The operator's day"): who may acknowledge or
shelve what, how long a shelving lasts, and what the list hides. Pure: the writer asks them
against the fault state inside its transaction, and every adapter gets the same answers."""

from __future__ import annotations

import re
from collections.abc import Iterable
from typing import NamedTuple

from faultledger.domain.clock import NS_PER_SECOND, from_ns
from faultledger.domain.events import FaultAcknowledged, FaultShelved, OperatorEvent
from faultledger.domain.fault import Fault
from faultledger.domain.types import FaultStatus
from faultledger.domain.validation import (
    MAX_ACTOR_LENGTH,
    MAX_DESCRIPTION_LENGTH,
    fault_code_error,
    shown,
    text_error,
)

MAX_SHELVE_NS = 30 * 86_400 * NS_PER_SECOND
"""The longest shelving: ISA-18.2 wants every shelving to end by itself; a month covers a
part on order, anything longer is a change of the configuration, not a shelving."""
EXPIRY_ACTOR = "timer"
"""Actor of the record that ends an expired shelving."""

_DURATION = re.compile(r"(?:(\d+)d)?(?:(\d+)h)?(?:(\d+)m)?(?:(\d+)s)?")
_UNIT_NS = (86_400 * NS_PER_SECOND, 3_600 * NS_PER_SECOND, 60 * NS_PER_SECOND, NS_PER_SECOND)


NOT_FOUND, CONFLICT = "not_found", "conflict"
"""The values of ``faultledger.errors.Reason`` a refusal carries (the domain imports no
other layer)."""


class Refusal(NamedTuple):
    """Why an operator action changes nothing: ``reason`` is a ``Reason`` value."""

    reason: str
    message: str


def parse_duration(text: str) -> int:
    """``2h``, ``90m``, ``1h30m``, ``1d``, ``45s`` → nanoseconds; ValueError naming the
    grammar otherwise (also for 0 and for more than MAX_SHELVE_NS)."""
    value = text.strip() if isinstance(text, str) else ""
    found = _DURATION.fullmatch(value) if value else None
    if found is None or not any(found.groups()):
        raise ValueError(f"a duration is a number with a unit d, h, m or s, combined in that "
                         f"order (2h, 90m, 1h30m, 1d), got {shown(text)}")
    total = sum(int(part) * unit for part, unit in zip(found.groups(), _UNIT_NS, strict=True)
                if part)
    return checked_duration(total)


def checked_duration(ns: int) -> int:
    if ns <= 0:
        raise ValueError("a shelving must last more than 0 s")
    if ns > MAX_SHELVE_NS:
        raise ValueError(f"a shelving lasts at most {MAX_SHELVE_NS // NS_PER_SECOND // 86_400} "
                         "days (ISA-18.2: every shelving ends by itself)")
    return ns


def input_error(fault_code: str, actor: str, text: str, text_name: str) -> str | None:
    """The first problem with an operator action's input (code, actor, note or reason)."""
    return (fault_code_error(fault_code)
            or (None if actor else "actor cannot be empty")
            or text_error("actor", actor, MAX_ACTOR_LENGTH)
            or text_error(text_name, text, MAX_DESCRIPTION_LENGTH))


def acknowledge_refusal(fault: Fault | None, fault_code: str) -> Refusal | None:
    """An acknowledgement needs a fault in an episode: not CLEARED (its episode is over;
    the next FAILED opens a new one, which needs its own acknowledgement)."""
    if fault is None:
        return Refusal(NOT_FOUND, f"Fault not found: {fault_code}")
    if fault.status is FaultStatus.CLEARED:
        return Refusal(CONFLICT, f"Fault {fault_code} is CLEARED: its episode is over, "
                       "nothing to acknowledge")
    return None


def already_acknowledged(fault: Fault) -> str | None:
    """The answer to a second acknowledgement of one episode (nothing is recorded)."""
    ack = fault.acknowledged
    if ack is None:
        return None
    return (f"Fault {fault.fault_code} episode {fault.episode} was already acknowledged by "
            f"{ack.actor} at {from_ns(ack.at_ns).isoformat()}")


def shelve_refusal(fault: Fault | None, fault_code: str) -> Refusal | None:
    """Any known fault can be shelved, a CLEARED one too (a nuisance that keeps coming back)."""
    if fault is None:
        return Refusal(NOT_FOUND, f"Fault not found: {fault_code}")
    return None


def unshelve_refusal(fault: Fault | None, fault_code: str) -> Refusal | None:
    if fault is None:
        return Refusal(NOT_FOUND, f"Fault not found: {fault_code}")
    if fault.shelved is None:
        return Refusal(CONFLICT, f"Fault {fault_code} is not shelved")
    return None


def expired_shelvings(faults: list[Fault], now_ns: int) -> list[Fault]:
    """Faults whose shelving has expired but is not yet ended by a record, oldest expiry
    first (the serving process records their ends in that order)."""
    due = [f for f in faults if f.shelved is not None and f.shelved.until_ns <= now_ns]
    return sorted(due, key=lambda f: (f.shelved.until_ns, f.fault_code))  # type: ignore[union-attr]


def done_message(event: OperatorEvent) -> str:
    code = event.fault_code
    if isinstance(event, FaultAcknowledged):
        return f"Fault acknowledged: {code} (episode {event.episode})"
    if isinstance(event, FaultShelved):
        return f"Fault shelved: {code} until {from_ns(event.until_ns).isoformat()}"
    return f"Fault unshelved: {code}"


SHELVED_VIEWS = ("hide", "only", "show")
"""What an operator's list does with shelved faults: hide them (the default), list only
them (the "shelved" filter), or show them among the others."""


def in_view(faults: Iterable[Fault], now_ns: int, shelved: str = "hide") -> list[Fault]:
    """The faults a view with ``shelved`` (SHELVED_VIEWS) shows, in their given order. An
    expired shelving no longer hides (``Fault.is_shelved``)."""
    if shelved not in SHELVED_VIEWS:
        raise ValueError(f"shelved must be one of {', '.join(SHELVED_VIEWS)}, got "
                         f"{shown(shelved)}")
    return [f for f in faults
            if shelved == "show" or f.is_shelved(now_ns) == (shelved == "only")]


def triage(faults: Iterable[Fault], now_ns: int, shelved: str = "hide") -> list[Fault]:
    """The operator's list: ``in_view``, unacknowledged faults first, by code within each
    group."""
    return sorted(in_view(faults, now_ns, shelved),
                  key=lambda f: (f.acknowledged is not None, f.fault_code))
