"""The debounce policy (SPEC §4.1): global thresholds, sanitising, per-source prefix overrides,
and per-fault-code pattern overrides (ours: the bridges' faults heal on their PASSED)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from fnmatch import fnmatchcase
from functools import cached_property
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, Field, field_validator

_T = TypeVar("_T")


def sanitise_confirmation(value: int) -> int:
    """A positive threshold is negated and 0 becomes -1, as medkit's fault manager does."""
    if value > 0:
        return -value
    return -1 if value == 0 else value


def sanitise_healing(value: int) -> int:
    return -value if value < 0 else value


@dataclass(frozen=True, slots=True)
class DebounceParams:
    """The three debounce fields in force for one report, after overrides are resolved."""

    confirmation_threshold: int
    healing_enabled: bool
    healing_threshold: int


class SourceOverride(BaseModel):
    """Any of the three debounce fields for sources under one prefix (or codes matching one
    pattern); unset fields inherit."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    confirmation_threshold: int | None = None
    healing_enabled: bool | None = None
    healing_threshold: int | None = None

    @field_validator("confirmation_threshold")
    @classmethod
    def _confirmation(cls, value: int | None) -> int | None:
        return None if value is None else sanitise_confirmation(value)

    @field_validator("healing_threshold")
    @classmethod
    def _healing(cls, value: int | None) -> int | None:
        return None if value is None else sanitise_healing(value)


class Policy(BaseModel):
    """Effective debounce configuration; recorded in the log whenever it changes."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    confirmation_threshold: int = -1
    healing_enabled: bool = False
    healing_threshold: int = 3
    auto_confirm_after_sec: float = Field(default=0.0, ge=0.0)
    overrides: Mapping[str, SourceOverride] = Field(default_factory=dict)
    code_overrides: Mapping[str, SourceOverride] = Field(default_factory=dict)
    """Fault code glob (fnmatch, case-sensitive: ``HW_*``) -> debounce fields. Of the
    patterns matching a code the most specific applies: the longest literal part before the
    first wildcard, then the longest pattern. A source override's fields win over it."""

    @field_validator("confirmation_threshold")
    @classmethod
    def _confirmation(cls, value: int) -> int:
        return sanitise_confirmation(value)

    @field_validator("healing_threshold")
    @classmethod
    def _healing(cls, value: int) -> int:
        return sanitise_healing(value)

    @field_validator("overrides")
    @classmethod
    def _prefixes(cls, value: Mapping[str, SourceOverride]) -> Mapping[str, SourceOverride]:
        for prefix in value:
            if not prefix:
                raise ValueError("an override prefix cannot be empty")
        return dict(sorted(value.items()))

    @field_validator("code_overrides")
    @classmethod
    def _patterns(cls, value: Mapping[str, SourceOverride]) -> Mapping[str, SourceOverride]:
        for pattern in value:
            if not pattern or len(pattern) > 256:
                raise ValueError("a code pattern must have 1 to 256 characters")
        return dict(sorted(value.items()))

    @cached_property
    def _by_length(self) -> tuple[tuple[str, SourceOverride], ...]:
        return tuple(sorted(self.overrides.items(), key=lambda item: -len(item[0])))

    @cached_property
    def _by_specificity(self) -> tuple[tuple[str, SourceOverride], ...]:
        return tuple(sorted(self.code_overrides.items(),
                            key=lambda item: (-len(_literal(item[0])), -len(item[0]), item[0])))

    @cached_property
    def _resolved(self) -> dict[str | tuple[str, str], DebounceParams]:
        return {}

    @property
    def defaults(self) -> DebounceParams:
        return DebounceParams(
            self.confirmation_threshold, self.healing_enabled, self.healing_threshold
        )

    def prefix_for(self, source_id: str) -> str | None:
        """The source prefix whose override applies to ``source_id``: the longest one equal
        to it or followed in it by '/' ("/a/b" covers "/a/b/c"); None: no prefix matches."""
        for prefix, _ in self._by_length:
            if source_id == prefix or (
                source_id.startswith(prefix) and source_id[len(prefix)] == "/"
            ):
                return prefix
        return None

    def pattern_for(self, fault_code: str) -> str | None:
        """The most specific code pattern matching ``fault_code``; None: no pattern does."""
        for pattern, _ in self._by_specificity:
            if fnmatchcase(fault_code, pattern):
                return pattern
        return None

    def override_for(self, source_id: str) -> SourceOverride | None:
        """The override of ``prefix_for(source_id)``, if any."""
        prefix = self.prefix_for(source_id)
        return None if prefix is None else self.overrides[prefix]

    def code_override_for(self, fault_code: str) -> SourceOverride | None:
        """The override of ``pattern_for(fault_code)``, if any."""
        pattern = self.pattern_for(fault_code)
        return None if pattern is None else self.code_overrides[pattern]

    def resolve(self, source_id: str, fault_code: str = "") -> DebounceParams:
        """Global values, then the code pattern's fields, then the source prefix's fields.
        ``domain.policy_explain.explain`` says the same per field, naming the rule that gave
        each (a property test keeps the two equal)."""
        key = (source_id, fault_code) if self.code_overrides else source_id
        cached = self._resolved.get(key)
        if cached is not None:
            return cached
        params = self.defaults
        if self.code_overrides:
            params = _apply(self.code_override_for(fault_code), params)
        params = _apply(self.override_for(source_id), params)
        if len(self._resolved) < 10_000:
            self._resolved[key] = params
        return params

    def to_record(self) -> dict[str, Any]:
        """Canonical form stored in a policy_changed record (unset override fields omitted)."""
        return self.model_dump(mode="json", exclude_none=True)


def _pick(value: _T | None, fallback: _T) -> _T:
    return fallback if value is None else value


def _apply(override: SourceOverride | None, params: DebounceParams) -> DebounceParams:
    if override is None:
        return params
    return DebounceParams(
        _pick(override.confirmation_threshold, params.confirmation_threshold),
        _pick(override.healing_enabled, params.healing_enabled),
        _pick(override.healing_threshold, params.healing_threshold),
    )


def _literal(pattern: str) -> str:
    """The part of a glob before its first wildcard."""
    cut = min((i for i, char in enumerate(pattern) if char in "*?["), default=len(pattern))
    return pattern[:cut]
