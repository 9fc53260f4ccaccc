"""Which rule of the debounce policy gives each field for one report, and where the policy makes
one fault code's thresholds depend on the reporting source (docs/configuration.md, "Explaining
the policy").

``explain`` mirrors ``Policy.resolve`` field by field (global value, then the most specific code
pattern's fields, then the longest source prefix's fields); a property test keeps the two
equal. The conflicts are ros2_medkit issue #276: the debounce counter belongs to the fault
code, but an override is chosen by the reporting source, so when two sources report one code
under different thresholds, whichever report arrives decides the transition and the other
policy is silently bypassed.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from enum import StrEnum

from faultledger.domain.fault import Fault
from faultledger.domain.policy import DebounceParams, Policy, SourceOverride

DEBOUNCE_FIELDS: tuple[str, ...] = (
    "confirmation_threshold", "healing_enabled", "healing_threshold")
"""The fields an override may set, in DebounceParams' order."""
GLOBAL_FIELDS: tuple[str, ...] = ("auto_confirm_after_sec",)
"""Fields only the global policy sets."""
SHARED_COUNTER = "the counter is shared per code; medkit #276"

Value = bool | int | float


class RuleKind(StrEnum):
    GLOBAL = "global"
    CODE = "code_overrides"
    SOURCE = "overrides"


@dataclass(frozen=True, slots=True)
class Rule:
    """One rule of the policy: the global values, one code pattern or one source prefix."""

    kind: RuleKind
    key: str = ""
    """The code pattern or source prefix; empty for the global values."""

    def __str__(self) -> str:
        if self.kind is RuleKind.GLOBAL:
            return self.kind.value
        return f"{self.kind.value} '{self.key}'"


GLOBAL = Rule(RuleKind.GLOBAL)


@dataclass(frozen=True, slots=True)
class FieldOrigin:
    """One field in force for a report: its value and the rule that gave it."""

    field: str
    value: Value
    rule: Rule


@dataclass(frozen=True, slots=True)
class Explanation:
    """The policy in force for a report of ``fault_code`` from ``source_id``, field by field."""

    source_id: str
    fault_code: str
    pattern: str | None
    """The code pattern chosen for the code (the most specific match); None: none matches."""
    prefix: str | None
    """The source prefix chosen for the source (the longest match); None: none matches."""
    fields: tuple[FieldOrigin, ...]
    """DEBOUNCE_FIELDS then GLOBAL_FIELDS, in that order."""

    def field(self, name: str) -> FieldOrigin:
        for found in self.fields:
            if found.field == name:
                return found
        raise KeyError(name)

    @property
    def params(self) -> DebounceParams:
        """The debounce fields as ``Policy.resolve`` gives them."""
        confirmation, healing, threshold = (self.field(name).value for name in DEBOUNCE_FIELDS)
        return DebounceParams(int(confirmation), bool(healing), int(threshold))


def explain(policy: Policy, source_id: str, fault_code: str) -> Explanation:
    """Every field in force for a report of ``fault_code`` from ``source_id``, with its rule."""
    pattern = policy.pattern_for(fault_code)
    prefix = policy.prefix_for(source_id)
    layers: list[tuple[Rule, SourceOverride]] = []
    if pattern is not None:
        layers.append((Rule(RuleKind.CODE, pattern), policy.code_overrides[pattern]))
    if prefix is not None:
        layers.append((Rule(RuleKind.SOURCE, prefix), policy.overrides[prefix]))
    fields: list[FieldOrigin] = []
    for name in DEBOUNCE_FIELDS:
        origin = FieldOrigin(name, getattr(policy, name), GLOBAL)
        for rule, override in layers:  # later layers win: the source prefix last
            value = getattr(override, name)
            if value is not None:
                origin = FieldOrigin(name, value, rule)
        fields.append(origin)
    fields.extend(FieldOrigin(name, getattr(policy, name), GLOBAL) for name in GLOBAL_FIELDS)
    return Explanation(source_id, fault_code, pattern, prefix, tuple(fields))


def shown_value(value: Value) -> str:
    """A value as the YAML configuration writes it (``true``, ``-3``, ``0.0``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


@dataclass(frozen=True, slots=True)
class RuleConflict:
    """A code pattern and a source prefix that set one field to different values: for codes the
    pattern governs, the field then depends on the reporting source."""

    pattern: str
    prefix: str
    field: str
    code_value: Value
    source_value: Value

    @property
    def message(self) -> str:
        code, source = shown_value(self.code_value), shown_value(self.source_value)
        return (f"policy: code_overrides '{self.pattern}' sets {self.field} {code}, overrides "
                f"'{self.prefix}' sets {source}: a code matching '{self.pattern}' reported from "
                f"under '{self.prefix}' gets {source}, from elsewhere {code} "
                f"({SHARED_COUNTER})")

    def concerns(self, policy: Policy, fault_code: str) -> bool:
        """Whether the pattern is the one chosen for ``fault_code``."""
        return policy.pattern_for(fault_code) == self.pattern


def rule_conflicts(policy: Policy) -> list[RuleConflict]:
    """Every (code pattern, source prefix, field) whose two values differ, in pattern, prefix
    and field order. Two source prefixes that differ are not a conflict: choosing thresholds by
    the source is what source overrides are for."""
    found: list[RuleConflict] = []
    for pattern, by_code in policy.code_overrides.items():
        for prefix, by_source in policy.overrides.items():
            for name in DEBOUNCE_FIELDS:
                code_value, source_value = getattr(by_code, name), getattr(by_source, name)
                if code_value is not None and source_value is not None and (
                        code_value != source_value):
                    found.append(RuleConflict(pattern, prefix, name, code_value, source_value))
    return found


MAX_SOURCES_SHOWN = 3
"""Sources named per group in a SourceConflict's message; the rest are counted."""


@dataclass(frozen=True, slots=True)
class SourceGroup:
    """Reporting sources of one fault that resolve to the same debounce fields."""

    sources: tuple[str, ...]
    explanation: Explanation
    """The first source's: the values, and the rules that gave them to it."""


@dataclass(frozen=True, slots=True)
class SourceConflict:
    """A fault whose recorded reporting sources resolve to different debounce fields."""

    fault_code: str
    groups: tuple[SourceGroup, ...]
    fields: tuple[str, ...]
    """The debounce fields whose values differ between the groups."""

    @property
    def message(self) -> str:
        count = sum(len(group.sources) for group in self.groups)
        parts = []
        for group in self.groups:
            named = ", ".join(f"'{source}'" for source in group.sources[:MAX_SOURCES_SHOWN])
            more = len(group.sources) - MAX_SOURCES_SHOWN
            if more > 0:
                named += f" and {more} more"
            values = ", ".join(
                f"{name} {shown_value(origin.value)} ({origin.rule})"
                for name in self.fields for origin in (group.explanation.field(name),))
            parts.append(f"{named}: {values}")
        return (f"policy: {self.fault_code} was reported by {count} sources under different "
                f"thresholds: {'; '.join(parts)} (whichever report arrives decides the "
                f"transition; {SHARED_COUNTER})")


def source_conflicts(policy: Policy, faults: Iterable[Fault]) -> list[SourceConflict]:
    """The faults whose ``reporting_sources`` resolve to different debounce fields under
    ``policy``, in the order given: one ``resolve`` per recorded source."""
    found: list[SourceConflict] = []
    for fault in faults:
        if len(fault.reporting_sources) < 2:
            continue
        conflict = _conflict(policy, fault.fault_code, fault.reporting_sources)
        if conflict is not None:
            found.append(conflict)
    return found


def _conflict(policy: Policy, fault_code: str, sources: Sequence[str]) -> SourceConflict | None:
    by_params: dict[DebounceParams, list[str]] = {}
    for source in sources:
        by_params.setdefault(policy.resolve(source, fault_code), []).append(source)
    if len(by_params) < 2:
        return None
    differing = tuple(name for name in DEBOUNCE_FIELDS
                      if len({getattr(params, name) for params in by_params}) > 1)
    groups = tuple(SourceGroup(tuple(named), explain(policy, named[0], fault_code))
                   for named in by_params.values())
    return SourceConflict(fault_code, groups, differing)
