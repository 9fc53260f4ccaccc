"""The diagnostics bridge's logic without ROS: settings, fault codes and the edge trigger.

``/diagnostics`` repeats every status about once a second whether or not anything changed. A
fault log must record changes, not samples, so the ``EdgeTracker`` remembers the last non-OK
level (and the code reported for it) per status and turns a stream of arrays into FAILED/PASSED
reports only when a level changes. Kept free of rclpy so it can be unit-tested directly;
``diagnostics.py`` feeds it ``DiagnosticStatus`` messages, which satisfy ``StatusLike``.
"""

from __future__ import annotations

import re
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

from pydantic import BaseModel, Field, field_validator

from faultledger.domain.validation import MAX_DESCRIPTION_LENGTH, fault_code_error
from faultledger.ros.bridges.codes import fault_code, upper_snake

# diagnostic_msgs/DiagnosticStatus level values (a ``byte`` field: rclpy gives ``bytes``).
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR", STALE: "STALE"}

MAX_PREFIX_LENGTH = 64
"""A prefix leaves at least 64 characters of the 128 for the part generated from the name."""
MAX_TRACKED = 10_000
"""Statuses remembered as failing at once; beyond this the oldest is forgotten (with a warning),
so a publisher inventing names cannot grow the bridge's memory without bound."""

_TOPIC = re.compile(r"^~?/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$|^/$")
_PREFIX = re.compile(r"^[A-Za-z0-9_.\-]*$")

Severity = int


class Settings(BaseModel):
    """``config/diagnostics.yaml``; every default is the documented behaviour."""

    topic: str = Field(default="/diagnostics", min_length=1)
    name_to_code: dict[str, str] = Field(default_factory=dict)
    code_key: str = ""
    code_prefix: str = Field(default="", max_length=MAX_PREFIX_LENGTH)
    source_from_hardware_id: bool = False
    exclude_names: list[str] = Field(default_factory=list)
    include_only_names: list[str] = Field(default_factory=list)
    stale_severity: int = Field(default=3, ge=0, le=3)
    warn_severity: int = Field(default=1, ge=0, le=3)
    error_severity: int = Field(default=2, ge=0, le=3)
    max_statuses: int = Field(default=1000, ge=1)
    reliability: Literal["reliable", "best_effort"] = "reliable"
    queue_depth: int = Field(default=100, ge=1, le=10_000)
    warn_interval_sec: float = Field(default=10.0, ge=0)

    @field_validator("topic")
    @classmethod
    def _topic_is_a_ros_name(cls, value: str) -> str:
        if not _TOPIC.match(value):
            raise ValueError("not a valid ROS topic name")
        return value

    @field_validator("code_prefix")
    @classmethod
    def _prefix_is_code_text(cls, value: str) -> str:
        if not _PREFIX.match(value) or ".." in value:
            raise ValueError("only A-Z a-z 0-9 _ - . are allowed in fault codes (and no '..')")
        return value

    @field_validator("exclude_names", "include_only_names")
    @classmethod
    def _no_empty_substrings(cls, value: list[str]) -> list[str]:
        if any(not s for s in value):
            raise ValueError("an empty substring would match every name")
        return value


class StatusLike(Protocol):
    """What the bridge reads of a ``diagnostic_msgs/DiagnosticStatus`` (read-only)."""

    @property
    def level(self) -> Any: ...  # bytes of length 1 from rclpy; int accepted

    @property
    def name(self) -> str: ...

    @property
    def message(self) -> str: ...

    @property
    def hardware_id(self) -> str: ...

    @property
    def values(self) -> Sequence[Any]: ...  # objects with .key and .value (KeyValue)


@dataclass(frozen=True)
class Report:
    """One report to make: ``passed`` False → FAILED with ``severity``."""

    passed: bool
    code: str
    source_id: str
    severity: Severity = 0
    description: str = ""


def level_of(raw: object) -> int | None:
    """The level as an int (0..3), or None when it is not one of the four defined levels."""
    if isinstance(raw, bytes | bytearray) and len(raw) == 1:
        value: int = raw[0]
    elif isinstance(raw, int) and not isinstance(raw, bool):
        value = raw
    else:
        return None
    return value if value in LEVEL_NAMES else None


def value_of(status: StatusLike, key: str) -> str | None:
    """The value of ``key`` in the status's key/value pairs (first match), else None."""
    for pair in status.values:
        if getattr(pair, "key", None) == key:
            value = getattr(pair, "value", "")
            return value if isinstance(value, str) else str(value)
    return None


@dataclass
class _Failing:
    level: int
    code: str
    source_id: str


class EdgeTracker:
    """Turns ``DiagnosticArray`` contents into edge-triggered reports.

    Per status key (the name; with ``source_from_hardware_id`` the name and hardware_id):
    first non-OK level → FAILED; another non-OK level, or another code for the same level →
    FAILED again (a changed code first gets PASSED for the old code); OK after non-OK →
    PASSED for the code that failed; anything else (same level again, first sight of OK) → no
    report. Only failing statuses are remembered.
    """

    def __init__(self, settings: Settings, bridge_source: str,
                 warn: Callable[[str, str], object]) -> None:
        self.settings = settings
        self.bridge_source = bridge_source
        self._warn = warn
        self._failing: OrderedDict[tuple[str, str], _Failing] = OrderedDict()
        self.name_to_code: dict[str, str] = {}
        for name, code in settings.name_to_code.items():
            problem = fault_code_error(code) if isinstance(code, str) else "not a string"
            if problem:
                warn("config", f"diagnostics.name_to_code[{name!r}]={code!r} is not a valid "
                               f"fault code ({problem}); the name gets a generated code")
            else:
                self.name_to_code[name] = code
        self._severity = {WARN: settings.warn_severity, ERROR: settings.error_severity,
                          STALE: settings.stale_severity}

    @property
    def failing(self) -> int:
        """How many statuses are currently remembered as failing."""
        return len(self._failing)

    def selected(self, name: str) -> bool:
        """include_only_names (any substring, when given) and not exclude_names."""
        s = self.settings
        if s.include_only_names and not any(part in name for part in s.include_only_names):
            return False
        return not any(part in name for part in s.exclude_names)

    def code_for(self, status: StatusLike) -> str | None:
        """name_to_code, else the ``code_key`` value, else the generated code; None: no code."""
        mapped = self.name_to_code.get(status.name)
        if mapped is not None:
            return mapped
        if self.settings.code_key:
            value = value_of(status, self.settings.code_key)
            if value is not None:
                value = value.strip()
                problem = fault_code_error(value)
                if not problem:
                    return value
                self._warn("code_value", f"diagnostics: status {status.name!r}: "
                           f"{self.settings.code_key}={value[:200]!r} is not a valid fault code "
                           f"({problem}); using the code generated from the name")
        if not upper_snake(status.name):
            self._warn("no_code", f"diagnostics: status name {status.name[:200]!r} has no "
                       "letter or digit to make a fault code of; status ignored (map it in "
                       "name_to_code)")
            return None
        return fault_code(status.name, prefix=self.settings.code_prefix)

    def source_for(self, status: StatusLike) -> str:
        if self.settings.source_from_hardware_id and status.hardware_id:
            return status.hardware_id
        return self.bridge_source

    def process(self, statuses: Sequence[StatusLike]) -> list[Report]:
        """The reports one received array causes (usually none)."""
        limit = self.settings.max_statuses
        if len(statuses) > limit:
            self._warn("too_many", f"diagnostics: array of {len(statuses)} statuses; only the "
                       f"first {limit} (max_statuses) are read")
            statuses = statuses[:limit]
        reports: list[Report] = []
        seen: set[tuple[str, str]] = set()
        for status in statuses:
            self._one(status, seen, reports)
        return reports

    def _one(self, status: StatusLike, seen: set[tuple[str, str]],
             reports: list[Report]) -> None:
        name = status.name
        if not isinstance(name, str) or not name.strip():
            self._warn("empty_name", "diagnostics: status with an empty name ignored")
            return
        if not self.selected(name):
            return
        level = level_of(status.level)
        if level is None:
            self._warn("bad_level", f"diagnostics: status {name[:200]!r} has unknown level "
                       f"{_show(status.level)} (expected 0 OK, 1 WARN, 2 ERROR, 3 STALE); "
                       "ignored")
            return
        hardware = status.hardware_id if self.settings.source_from_hardware_id else ""
        key = (name, hardware or "")
        if key in seen:
            self._warn("duplicate", f"diagnostics: status {name[:200]!r} appears twice in one "
                       "array; the first one counts")
            return
        seen.add(key)
        before = self._failing.get(key)
        if level == OK:
            if before is not None:
                del self._failing[key]
                reports.append(Report(True, before.code, before.source_id))
            return
        if before is not None and before.level == level and not self.settings.code_key:
            return  # the common case: same level again; only a code_key value can change codes
        code = self.code_for(status)
        if code is None:
            return
        if before is not None and before.level == level and before.code == code:
            return
        source = self.source_for(status)
        if before is not None and before.code != code:
            reports.append(Report(True, before.code, before.source_id))
        reports.append(Report(False, code, source, self._severity[level],
                              describe(status, level)))
        self._failing[key] = _Failing(level, code, source)
        self._failing.move_to_end(key)
        if len(self._failing) > MAX_TRACKED:
            (old_name, _), _old = self._failing.popitem(last=False)
            self._warn("tracked", f"diagnostics: more than {MAX_TRACKED} failing statuses; "
                       f"forgot {old_name[:200]!r} (its next report may repeat)")


def describe(status: StatusLike, level: int) -> str:
    """The FAILED description: ``<name> [<LEVEL>]: <message> (hardware_id: <id>)``."""
    text = f"{status.name} [{LEVEL_NAMES[level]}]"
    if status.message:
        text += f": {status.message}"
    if status.hardware_id:
        text += f" (hardware_id: {status.hardware_id})"
    return text if len(text) <= MAX_DESCRIPTION_LENGTH else text[: MAX_DESCRIPTION_LENGTH - 3] \
        + "..."


def _show(raw: object) -> str:
    if isinstance(raw, bytes | bytearray) and len(raw) == 1:
        return str(raw[0])
    return repr(raw)[:50]

