"""Alert rules (docs/alerts.md): which changes a rule sends, what one alert says, and the key
that makes its delivery idempotent. Pure: the deliverer's scan asks these against the faults
it replays from the log, so a restarted scan decides exactly as the first one did."""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field
from fnmatch import fnmatchcase
from typing import Any

from faultledger.domain.clock import NS_PER_SECOND, from_ns
from faultledger.domain.fault import Fault
from faultledger.domain.types import NotificationType, Severity, severity_name
from faultledger.domain.validation import shown

RECORD_EVENTS = (NotificationType.CONFIRMED.value, NotificationType.UPDATED.value,
                 NotificationType.CLEARED.value, NotificationType.ACKNOWLEDGED.value)
"""Announcements of one log record that a rule may send (docs/semantics.md)."""
FLOOD, STALE, SYNC_LAG = "flood", "stale", "sync_lag"
DERIVED_EVENTS = (FLOOD, STALE, SYNC_LAG)
"""Conditions of several records or of time (docs/statistics.md, "Alarm-management KPIs";
docs/fleet.md, "Lag"), each anchored at one seq."""
ALERT_EVENTS = RECORD_EVENTS + DERIVED_EVENTS
NOT_ALERTS = {
    NotificationType.SHELVED.value: "a shelved fault alerts nothing",
    NotificationType.UNSHELVED.value: "the fault's next change alerts again",
}
"""Announcements that are no alert event, and why (said when a rule names one)."""

RECEIVER_TYPES = ("webhook", "slack", "pagerduty")
PAGERDUTY_ACTIONS = {NotificationType.CONFIRMED.value: "trigger",
                     NotificationType.ACKNOWLEDGED.value: "acknowledge",
                     NotificationType.CLEARED.value: "resolve",
                     FLOOD: "trigger", STALE: "trigger", SYNC_LAG: "trigger"}
"""Events API v2 ``event_action`` per event; fault_updated has none (PagerDuty would only
deduplicate it into the open incident), so a pagerduty rule may not name it."""

RULE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}")
RULE_NAME_RULE = "1..64 characters: ASCII letters, digits, _ . -, starting with a letter or digit"
MAX_GLOBS = 256
MAX_GLOB_LENGTH = 256

FLOOD_WINDOW_NS = 600 * NS_PER_SECOND
"""The 10-minute grid of the flood KPI (UTC, aligned to the epoch)."""
FLOOD_MORE_THAN = 10
"""A window with more confirmations than this is in flood."""
STALE_AFTER_NS = 86_400 * NS_PER_SECOND
"""CONFIRMED this long (or longer) is stale."""
DEFAULT_SYNC_LAG_SECONDS = 300.0
CONFIRMED = NotificationType.CONFIRMED.value

BACKOFF_FIRST_SEC = 0.5
BACKOFF_MAX_SEC = 30.0


def glob_error(pattern: object) -> str | None:
    """A code glob (fnmatch, case-sensitive) as a rule may hold it; the message or None."""
    if not isinstance(pattern, str):
        return f"a code glob must be a string, got {shown(pattern)}"
    if not pattern:
        return "a code glob cannot be empty"
    if len(pattern) > MAX_GLOB_LENGTH:
        return f"a code glob is at most {MAX_GLOB_LENGTH} characters, got {len(pattern)}"
    if "\x00" in pattern:
        return f"a code glob cannot contain a NUL character: {shown(pattern)}"
    i = 0
    while i < len(pattern):
        if pattern[i] == "[":
            j = i + 1  # fnmatch's reading: [!...] negates, a ] right after [ or [! is literal
            if j < len(pattern) and pattern[j] == "!":
                j += 1
            if j < len(pattern) and pattern[j] == "]":
                j += 1
            while j < len(pattern) and pattern[j] != "]":
                j += 1
            if j >= len(pattern):
                return f"unbalanced '[' at position {i} in {shown(pattern)}"
            i = j
        i += 1
    return None


def parse_severity(value: object) -> int:
    """0-3 or INFO/WARN/ERROR/CRITICAL (any case); ValueError naming both forms."""
    if isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= 3:
        return value
    if isinstance(value, str) and value.strip().upper() in Severity.__members__:
        return int(Severity[value.strip().upper()])
    raise ValueError(f"must be 0-3 or INFO/WARN/ERROR/CRITICAL, got {shown(value)}")


def selects(codes: tuple[str, ...], min_severity: int, code: str, severity: int) -> bool:
    """Whether a rule's ``codes`` and ``min_severity`` select a fault (its severity after the
    record)."""
    return severity >= min_severity and any(fnmatchcase(code, glob) for glob in codes)


def alerts_for(fault: Fault, at_ns: int) -> bool:
    """A fault alerts unless it is shelved at ``at_ns`` (the record's recording time)."""
    return not fault.is_shelved(at_ns)


def key(ledger_id: str, seq: int, rule: str, event: str, suffix: str = "") -> str:
    """The idempotency key: ledger_id, seq and rule (SPEC: "ledger_id + seq + receiver").
    A record announces one change, so its events need no more; a derived event names
    itself, since its anchor is a record that may alert too (flood: the confirmation that
    made the window a flood; stale: the fault's confirming record)."""
    base = f"{ledger_id}:{seq}:{rule}"
    if event in RECORD_EVENTS:
        return base
    return f"{base}:{event}{suffix}"


def flood_window(occurred_ns: int) -> int:
    """The start of the 10-minute window (UTC grid) a confirmation counts in."""
    return occurred_ns - occurred_ns % FLOOD_WINDOW_NS


def backoff_sec(attempts: int, jitter: float) -> float:
    """The wait before attempt ``attempts + 1`` after ``attempts`` failed ones: 0.5 s doubling
    up to 30 s, times 0.75..1.25 (``jitter`` in [0, 1)), never above 30 s."""
    base = min(BACKOFF_MAX_SEC, BACKOFF_FIRST_SEC * 2.0 ** max(0, attempts - 1))
    return min(BACKOFF_MAX_SEC, base * (0.75 + 0.5 * jitter))


@dataclass(frozen=True, slots=True)
class Alert:
    """What one delivery says, whatever the receiver: stored in the outbox as JSON when the
    scan decides it, turned into a receiver's body when it is sent."""

    event: str
    key: str
    seq: int
    ledger_id: str
    robot_id: str
    occurred_ns: int
    incident: str
    """What the alert is about, across its events: ``ledger_id:code:episode`` for a fault's
    episode (PagerDuty's dedup_key)."""
    fault_code: str | None = None
    severity: int | None = None
    status: str | None = None
    episode: int | None = None
    description: str = ""
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def occurred_at(self) -> str:
        return from_ns(self.occurred_ns).isoformat()

    @property
    def severity_text(self) -> str | None:
        return None if self.severity is None else severity_name(self.severity)

    def to_json(self) -> str:
        return json.dumps(asdict(self), ensure_ascii=False, separators=(",", ":"),
                          sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> Alert:
        return cls(**json.loads(text))


def fault_alert(event: str, rule: str, seq: int, ledger_id: str, robot_id: str,
                occurred_ns: int, fault: Fault) -> Alert:
    """The alert of a record's announcement about ``fault`` (its state after the record)."""
    return Alert(event, key(ledger_id, seq, rule, event), seq, ledger_id, robot_id,
                 occurred_ns, episode_incident(ledger_id, fault), fault.fault_code,
                 fault.severity, fault.status.value, fault.episode, fault.description)


def episode_incident(ledger_id: str, fault: Fault) -> str:
    return f"{ledger_id}:{fault.fault_code}:{fault.episode}"
