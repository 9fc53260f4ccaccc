"""`faultledger policy explain`: the debounce fields in force for one report and the rule that
gave each (docs/cli.md, "policy explain"; docs/configuration.md, "Explaining the policy").
Registered by cli/main.py."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from faultledger.cli import render
from faultledger.cli.options import (
    HELP_MARKUP,
    ConfigOption,
    JsonOption,
    WideOption,
    fail,
    opened,
    prepare,
    settings_for,
)
from faultledger.cli.safe_text import cell
from faultledger.domain.fault import Fault
from faultledger.domain.policy_explain import shown_value
from faultledger.errors import FaultLedgerError
from faultledger.service.config import config_path
from faultledger.service.policy_check import PolicyAnswer, answer, explain_report

policy_app = typer.Typer(help="The debounce policy of the configuration.", no_args_is_help=True,
                         rich_markup_mode=HELP_MARKUP)


def register(app: typer.Typer) -> None:
    app.add_typer(policy_app, name="policy")


@policy_app.command("explain")
def policy_explain(
    fault_code: Annotated[str, typer.Argument(
        metavar="FAULT_CODE", help="The fault code a report would carry.")],
    source: Annotated[str, typer.Option(
        "--source", metavar="ID", help="The source_id that would report it.")],
    db: Annotated[str | None, typer.Option(
        "--db", metavar="URL|PATH",
        help="Also check the faults this database knows (read only): a fault whose "
        "reporting sources get different thresholds under the config's policy is "
        "warned of. Not taken from FAULTLEDGER_DB or the config: only when given.")] = None,
    as_json: JsonOption = False,
    wide: WideOption = False,
    config: ConfigOption = None,
) -> None:
    """The debounce thresholds a report of FAULT_CODE from --source gets, and which rule
    gave each.

    The rules: the global values, the most specific matching code pattern
    (policy.code_overrides), the longest matching source prefix (policy.overrides); a source
    prefix's field beats a code pattern's. Warns when the code's thresholds depend on the
    reporting source (the counter is shared per code; medkit #276).
    """
    settings = settings_for(config)
    try:
        explain_report(settings.policy, source, fault_code)  # bad input: before any database
    except FaultLedgerError as error:
        fail(str(error))
    faults: list[Fault] | None = None
    if db is not None:
        with opened(prepare(db, config)) as ledger:
            faults = ledger.all_faults()
    try:
        found = answer(settings.policy, source, fault_code, faults)
    except FaultLedgerError as error:
        fail(str(error))
    path = config_path(config)
    if as_json:
        typer.echo(json.dumps(_as_dict(found, path), indent=2))
        return
    out = render.console(wide=wide)
    out.print(_table(found, path))
    for warning in found.warnings:
        render.warn(warning)
    if found.others:
        render.note(f"the policy has warnings about other codes too ({', '.join(found.others)})"
                    "; explain a code they concern to see them")


def _where(path: Path | None) -> str:
    return "built-in defaults" if path is None else str(path)


def _table(found: PolicyAnswer, path: Path | None) -> Table:
    explanation = found.explanation
    table = Table(title=cell(f"{explanation.fault_code} from {explanation.source_id} "
                             f"({_where(path)})"), title_justify="left")
    table.add_column("field", no_wrap=True)
    table.add_column("value", no_wrap=True, justify="right")
    table.add_column("from", overflow="fold")
    for origin in explanation.fields:
        table.add_row(cell(origin.field), cell(shown_value(origin.value)), cell(str(origin.rule)))
    return table


def _as_dict(found: PolicyAnswer, path: Path | None) -> dict[str, Any]:
    explanation = found.explanation
    return {
        "fault_code": explanation.fault_code,
        "source_id": explanation.source_id,
        "config": None if path is None else str(path),
        "code_pattern": explanation.pattern,
        "source_prefix": explanation.prefix,
        "fields": {origin.field: {"value": origin.value, "from": str(origin.rule),
                                  "rule": origin.rule.kind.value,
                                  "key": origin.rule.key or None}
                   for origin in explanation.fields},
        "warnings": found.warnings,
        "other_warnings": list(found.others),
        "ledger_checked": found.ledger_checked,
    }
