"""The debounce policy explained, and its warnings, for the adapters: `faultledger policy
explain`, a writing command given ``--config``, and the start of `serve` and `faultledger http`
(docs/configuration.md, "Explaining the policy").

Warnings never stop anything: the adapters print them on stderr or log them.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from faultledger.domain import validation
from faultledger.domain.fault import Fault
from faultledger.domain.policy import Policy
from faultledger.domain.policy_explain import (
    Explanation,
    RuleConflict,
    SourceConflict,
    explain,
    rule_conflicts,
    source_conflicts,
)
from faultledger.errors import InvalidInputError
from faultledger.service.ledger import FaultLedger

MAX_LEDGER_WARNINGS = 20
"""Faults named one by one at start; more are counted in one more warning."""


def explain_report(policy: Policy, source_id: str, fault_code: str) -> Explanation:
    """The fields in force for a report of ``fault_code`` from ``source_id``; a code or source
    a report could not carry is refused (``InvalidInputError``, the report's own message)."""
    problem = validation.fault_code_error(fault_code)
    if problem is None and isinstance(source_id, str) and not source_id:
        problem = "source_id cannot be empty"
    problem = problem or validation.text_error("source_id", source_id,
                                               validation.MAX_SOURCE_ID_LENGTH)
    if problem is not None:
        raise InvalidInputError(problem)
    return explain(policy, source_id, fault_code)


@dataclass(frozen=True, slots=True)
class PolicyAnswer:
    """`policy explain`'s answer: the fields and the warnings that concern the code."""

    explanation: Explanation
    rule_conflicts: tuple[RuleConflict, ...]
    """The policy's conflicts of the code pattern chosen for the code."""
    source_conflict: SourceConflict | None
    """With a ledger: the code's fault, when its reporting sources resolve differently."""
    others: tuple[str, ...]
    """What the policy's other warnings concern: ``code_overrides 'P'`` or a fault code."""
    ledger_checked: bool

    @property
    def warnings(self) -> list[str]:
        found = [conflict.message for conflict in self.rule_conflicts]
        if self.source_conflict is not None:
            found.append(self.source_conflict.message)
        return found


def answer(policy: Policy, source_id: str, fault_code: str,
           faults: Iterable[Fault] | None = None) -> PolicyAnswer:
    """``explain_report``, and the policy's warnings: of the code (the conflicts of the pattern
    chosen for it; with ``faults``, the code's own fault) and, as subjects only, the others."""
    explanation = explain_report(policy, source_id, fault_code)
    static = rule_conflicts(policy)
    mine = tuple(c for c in static if c.pattern == explanation.pattern)
    others = [f"code_overrides '{c.pattern}'" for c in static if c.pattern != explanation.pattern]
    source_conflict: SourceConflict | None = None
    for conflict in source_conflicts(policy, faults or ()):
        if conflict.fault_code == fault_code:
            source_conflict = conflict
        else:
            others.append(conflict.fault_code)
    return PolicyAnswer(explanation, mine, source_conflict, tuple(dict.fromkeys(others)),
                        faults is not None)


def config_warnings(policy: Policy) -> list[str]:
    return [conflict.message for conflict in rule_conflicts(policy)]


def ledger_warnings(policy: Policy, faults: Iterable[Fault]) -> list[str]:
    """One warning per fault whose sources resolve to different fields; after
    ``MAX_LEDGER_WARNINGS`` of them, one more counts the rest."""
    found = source_conflicts(policy, faults)
    shown = [conflict.message for conflict in found[:MAX_LEDGER_WARNINGS]]
    rest = found[MAX_LEDGER_WARNINGS:]
    if rest:
        codes = ", ".join(conflict.fault_code for conflict in rest[:5])
        shown.append(f"policy: {len(rest)} more faults were reported by sources under "
                     f"different thresholds ({codes}{', …' if len(rest) > 5 else ''}); "
                     "`faultledger policy explain CODE --source S --db …` shows each")
    return shown


def startup_warnings(ledger: FaultLedger) -> list[str]:
    """What a serving process warns of when it opens ``ledger``: the conflicts of the policy in
    force (``ledger.policy``), then its faults' (one pass over the faults it knows)."""
    policy = ledger.policy
    return config_warnings(policy) + ledger_warnings(policy, ledger.all_faults())
