"""Checks PromQL against what a live ``/metrics`` exposes (docs/grafana/README.md).

Expressions are parsed with ``promql-parser`` (the Python binding of GreptimeTeam's Rust PromQL
parser), so function names, keywords, durations, strings and grouping clauses are never taken
for metric names. ``problems(expr, scrape)`` names everything in an expression that the scrape
does not back: a series name it lacks, a label name that series lacks, a label value (``=``,
``!=``) it never shows, a regex (``=~``, ``!~``) that matches none of its values, a ``by``,
``without``, ``on`` or ``ignoring`` label none of the selectors below it has.

Grafana's own variables (``$__rate_interval``…) and a dashboard's template variables
(``$job``, ``${job}``, ``[[job]]``) must be substituted first (``substitute``): PromQL has no
``$``.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import promql_parser
from prometheus_client.parser import text_string_to_metric_families

PROMETHEUS_OWN = frozenset({"up"})
"""Series Prometheus itself writes for every scrape target, so no scrape of ours shows them:
``up`` (1 when the target's last scrape worked, 0 when it failed). Allowed explicitly, by
name, so that any other name must come from ``/metrics``."""
TARGET_LABELS = frozenset({"job", "instance"})
"""Labels Prometheus attaches to every series of a target from its scrape config; a scrape
never shows them and their values depend on that config, so only their names are allowed."""
GRAFANA_BUILTINS = {"__rate_interval": "1m", "__interval": "1m", "__range": "1h"}
"""Grafana's global variables a dashboard here may use, with a value of the right kind."""

_VARIABLE = re.compile(r"\$\{(\w+)(?::\w+)?\}|\$(\w+)|\[\[(\w+)(?::\w+)?\]\]")
_OPS = ((promql_parser.MatchOp.Equal, "="), (promql_parser.MatchOp.NotEqual, "!="),
        (promql_parser.MatchOp.Re, "=~"), (promql_parser.MatchOp.NotRe, "!~"))
"""Pairs, not a dict: the binding's enums compare equal but do not hash."""


@dataclass(frozen=True)
class Scrape:
    """What one ``/metrics`` text shows: per series name, each label and its values."""

    series: dict[str, dict[str, set[str]]]
    families: dict[str, set[str]]
    """Per metric family, the series names of its samples."""
    values: dict[tuple[str, frozenset[tuple[str, str]]], float]

    @classmethod
    def parse(cls, text: str) -> Scrape:
        series: dict[str, dict[str, set[str]]] = {}
        families: dict[str, set[str]] = {}
        values: dict[tuple[str, frozenset[tuple[str, str]]], float] = {}
        for family in text_string_to_metric_families(text):
            for sample in family.samples:
                labels = series.setdefault(sample.name, {})
                for label, value in sample.labels.items():
                    labels.setdefault(label, set()).add(value)
                families.setdefault(family.name, set()).add(sample.name)
                values[sample.name, frozenset(sample.labels.items())] = sample.value
        return cls(series, families, values)

    def value(self, name: str, **labels: str) -> float | None:
        return self.values.get((name, frozenset(labels.items())))


@dataclass(frozen=True)
class Selector:
    """One vector selector: ``name{label op "value", …}``; ``name`` is None for a selector
    that names its metric only by a regex on ``__name__`` (which this check refuses)."""

    name: str | None
    matchers: tuple[tuple[str, str, str], ...]
    """(label, op, value) with op one of ``=``, ``!=``, ``=~``, ``!~``; no ``__name__``."""
    or_matchers: bool = False


@dataclass(frozen=True)
class Grouping:
    """Labels an aggregation (``by``/``without``) or a vector match (``on``/``ignoring``,
    ``group_left``/``group_right``) names, and the selectors below it."""

    clause: str
    labels: tuple[str, ...]
    selectors: tuple[Selector, ...]


def substitute(expr: str, variables: Mapping[str, str]) -> str:
    """``expr`` with every Grafana variable replaced by ``variables`` or a Grafana built-in;
    ValueError names one that is neither."""
    known = {**GRAFANA_BUILTINS, **variables}

    def value(found: re.Match[str]) -> str:
        name = next(group for group in found.groups() if group is not None)
        if name not in known:
            raise ValueError(f"unknown Grafana variable ${name}")
        return known[name]

    return _VARIABLE.sub(value, expr)


def _selector(node: promql_parser.VectorSelector) -> Selector:
    name = node.name
    matchers = []
    for matcher in node.matchers.matchers:
        op = next(text for kind, text in _OPS if kind == matcher.op)
        if matcher.name == "__name__" and op == "=" and name is None:
            name = matcher.value
        elif matcher.name == "__name__":
            name = None  # a regex on the name, or a second name: nothing to check against
            break
        else:
            matchers.append((matcher.name, op, matcher.value))
    return Selector(name, tuple(matchers), bool(node.matchers.or_matchers))


def _collect(expr: promql_parser.Expr) -> tuple[list[Selector], list[Grouping]]:
    selectors: list[Selector] = []
    groupings: list[Grouping] = []

    def visit(node: promql_parser.Expr) -> None:
        if isinstance(node, promql_parser.VectorSelector):
            selectors.append(_selector(node))
        elif isinstance(node, promql_parser.AggregateExpr) and node.modifier is not None:
            clause = "by" if node.modifier.type == promql_parser.AggModifierType.By \
                else "without"
            groupings.append(Grouping(clause, tuple(node.modifier.labels),
                                      tuple(_collect(node.expr)[0])))
        elif isinstance(node, promql_parser.BinaryExpr) and node.modifier is not None:
            below = tuple(_collect(node.lhs)[0] + _collect(node.rhs)[0])
            matching = node.modifier.matching
            if matching is not None:
                clause = "on" if matching.type == promql_parser.LabelModifierType.Include \
                    else "ignoring"
                groupings.append(Grouping(clause, tuple(matching.labels), below))
            if node.modifier.group_labels:
                groupings.append(Grouping("group_left/group_right",
                                          tuple(node.modifier.group_labels), below))

    promql_parser.walk(expr, pre_visit=visit)
    return selectors, groupings


def selectors(expr: str) -> list[Selector]:
    """Every vector selector in ``expr`` (ValueError when it does not parse)."""
    return _collect(promql_parser.parse(expr))[0]


def metric_names(expr: str) -> set[str]:
    return {s.name for s in selectors(expr) if s.name is not None}


def _labels_of(selector: Selector, scrape: Scrape) -> set[str]:
    if selector.name is None or selector.name in PROMETHEUS_OWN:
        return set(TARGET_LABELS)
    return set(scrape.series.get(selector.name, {})) | TARGET_LABELS


def labels_of(expr: str, scrape: Scrape) -> set[str]:
    """Every label a series that ``expr`` selects may carry: a superset of what its result
    carries, good enough to catch a misspelt ``{{label}}`` in a legend or an annotation."""
    found: set[str] = set()
    for selector in selectors(expr):
        found |= _labels_of(selector, scrape)
    return found


def _selector_problems(selector: Selector, scrape: Scrape) -> Iterator[str]:
    if selector.name is None:
        yield "a selector without a literal metric name cannot be checked"
        return
    if selector.or_matchers:
        yield f"{selector.name}: `or` inside a selector cannot be checked"
    if selector.name in PROMETHEUS_OWN:
        for label, _, _ in selector.matchers:
            if label not in TARGET_LABELS:
                yield f"{selector.name}: label {label!r} is not one Prometheus attaches"
        return
    labels = scrape.series.get(selector.name)
    if labels is None:
        close = difflib.get_close_matches(selector.name, scrape.series, n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        yield f"{selector.name}: no such series in /metrics{hint}"
        return
    for label, op, value in selector.matchers:
        if label in TARGET_LABELS:
            continue
        if label not in labels:
            yield (f"{selector.name}: no label {label!r} (it has "
                   f"{', '.join(sorted(labels)) or 'none'})")
            continue
        shown = labels[label]
        if op in ("=", "!=") and value not in shown:
            yield (f"{selector.name}{{{label}{op}{value!r}}}: /metrics shows no such value "
                   f"(it shows {', '.join(sorted(shown))})")
        elif op in ("=~", "!~") and not any(re.fullmatch(value, v) for v in shown):
            yield (f"{selector.name}{{{label}{op}{value!r}}}: the regex matches no value "
                   f"/metrics shows ({', '.join(sorted(shown))})")


def problems(expr: str, scrape: Scrape) -> list[str]:
    """What in ``expr`` the scrape does not back; empty when everything is there."""
    try:
        found, groupings = _collect(promql_parser.parse(expr))
    except ValueError as error:
        return [f"does not parse: {error}"]
    if not found:
        return ["selects no series"]
    listed = [problem for selector in found for problem in _selector_problems(selector, scrape)]
    for grouping in groupings:
        below: set[str] = set()
        for selector in grouping.selectors:
            below |= _labels_of(selector, scrape)
        listed += [f"{grouping.clause} ({label}): no series below it has that label"
                   for label in grouping.labels if label not in below]
    return listed


LABEL_VALUES = re.compile(r"^\s*label_values\((.+),\s*(\w+)\s*\)\s*$", re.DOTALL)
TEMPLATE_LABEL = re.compile(r"\{\{\s*(\w+)\s*\}\}")
"""``{{label}}`` in a Grafana legend."""
ANNOTATION_LABEL = re.compile(r"\$labels\.(\w+)")
"""``{{ $labels.label }}`` in a Prometheus rule's labels and annotations."""


def variable_query_problems(query: str, scrape: Scrape) -> list[str]:
    """A Grafana query variable ``label_values(selector, label)``."""
    found = LABEL_VALUES.match(query)
    if found is None:
        return [f"{query!r}: only label_values(selector, label) is checked"]
    selector, label = found.groups()
    listed = problems(selector, scrape)
    if not listed and label not in labels_of(selector, scrape):
        listed.append(f"label_values: no label {label!r} on {selector}")
    return listed


def panels(items: list[dict[str, Any]]) -> Iterator[dict[str, Any]]:
    """Every panel, rows' nested panels (a collapsed row keeps its own) included."""
    for panel in items:
        yield panel
        yield from panels(panel.get("panels", []))
