"""The debounce policy (SPEC §4.1): global thresholds, sanitising, per-source prefix overrides."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
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
    """Any of the three debounce fields for sources under one prefix; unset fields inherit."""

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

    @cached_property
    def _by_length(self) -> tuple[tuple[str, SourceOverride], ...]:
        return tuple(sorted(self.overrides.items(), key=lambda item: -len(item[0])))

    @cached_property
    def _resolved(self) -> dict[str, DebounceParams]:
        return {}

    @property
    def defaults(self) -> DebounceParams:
        return DebounceParams(
            self.confirmation_threshold, self.healing_enabled, self.healing_threshold
        )

    def override_for(self, source_id: str) -> SourceOverride | None:
        """Longest prefix equal to source_id or followed in it by '/' ("/a/b" covers "/a/b/c")."""
        for prefix, override in self._by_length:
            if source_id == prefix or (
                source_id.startswith(prefix) and source_id[len(prefix)] == "/"
            ):
                return override
        return None

    def resolve(self, source_id: str) -> DebounceParams:
        cached = self._resolved.get(source_id)
        if cached is not None:
            return cached
        override = self.override_for(source_id)
        params = self.defaults
        if override is not None:
            params = DebounceParams(
                _pick(override.confirmation_threshold, params.confirmation_threshold),
                _pick(override.healing_enabled, params.healing_enabled),
                _pick(override.healing_threshold, params.healing_threshold),
            )
        if len(self._resolved) < 10_000:
            self._resolved[source_id] = params
        return params

    def to_record(self) -> dict[str, Any]:
        """Canonical form stored in a policy_changed record (unset override fields omitted)."""
        return self.model_dump(mode="json", exclude_none=True)


def _pick(value: _T | None, fallback: _T) -> _T:
    return fallback if value is None else value
