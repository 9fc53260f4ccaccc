"""`faultledger alerts`: the alert rules' state and their deliveries (docs/alerts.md), as a
table that fits the terminal or as the JSON of GET /api/v1/alerts."""

from __future__ import annotations

import json
import time
from typing import Annotated

import typer
from rich.console import RenderableType

from faultledger.cli import render
from faultledger.cli.options import (
    ConfigOption,
    DbOption,
    JsonOption,
    WideOption,
    fail,
    opened,
    prepare,
)
from faultledger.cli.render import Column, Entry, Short
from faultledger.cli.safe_text import cell
from faultledger.domain.clock import NS_PER_SECOND
from faultledger.errors import FaultLedgerError
from faultledger.service import alerts
from faultledger.store.alert_outbox import Delivery

_STATE_STYLE = {"pending": "yellow", "retrying": "bold yellow", "delivered": "green",
                "failed": "bold red"}


def alerts_command(
    rule: Annotated[str | None, typer.Option(
        "--rule", metavar="NAME", help="Only this rule's deliveries.")] = None,
    state: Annotated[list[str] | None, typer.Option(
        "--state", metavar="STATE",
        help="Only deliveries in this state: pending, retrying, delivered, failed "
        "(repeatable).")] = None,
    limit: Annotated[int, typer.Option(
        "--limit", metavar="N", help=f"Newest deliveries shown (1-{alerts.MAX_LISTED}).")
    ] = 50,
    as_json: JsonOption = False,
    wide: WideOption = False,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """List alert deliveries, newest first, and each rule's state.

    Per delivery: rule, event, fault code, state (pending, retrying, delivered, failed),
    attempts, last error, lag (undelivered: how long it has been due; delivered: how long
    it took) and idempotency key.
    """
    with opened(prepare(db, config)) as ledger:
        try:
            found = alerts.deliveries(ledger, rule, state or (), limit)
            rules = [r for r in alerts.rule_states(ledger) if rule is None or r.rule == rule]
        except FaultLedgerError as error:
            fail(str(error))
    now = time.time_ns()
    if as_json:
        typer.echo(json.dumps({"rules": [alerts.rule_dict(r, now) for r in rules],
                               "deliveries": [alerts.delivery_dict(d, now) for d in found]},
                              indent=2))
        return
    out = render.console(wide=wide)
    width = render.fit_width(out, wide)
    if not rules:
        out.print(cell("no alert rule has run on this database (the config's alerts: are "
                       "delivered by serve and faultledger http)"))
        return
    for line in (_rule_line(alerts.rule_dict(r, now)) for r in rules):
        out.print(cell(line))
    out.print(deliveries_table(found, now, width))


def _rule_line(data: dict[str, object]) -> str:
    counts = data["deliveries"]
    assert isinstance(counts, dict)
    oldest = data["oldest_undelivered_seconds"]
    holder = data["holder"] or "nobody (not delivering)"
    line = (f"rule {data['rule']}: scanned to seq {data['cursor']}, held by {holder}; "
            + ", ".join(f"{counts[s]} {s}" for s in ("pending", "retrying", "failed",
                                                       "delivered")))
    if isinstance(oldest, int | float):
        line += f"; oldest undelivered due {duration(oldest)} ago"
    return line


def deliveries_table(found: list[Delivery], now_ns: int, width: int | None
                     ) -> RenderableType:
    """When narrow, the key goes first, then the tries, then the code; the rule, event, code
    and key are shown shorter before that, and the last error folds over lines."""
    columns = (Column("rule", no_wrap=True, squeeze=6),
               Column("event", no_wrap=True, squeeze=8),
               Column("code", no_wrap=True, drop=4, squeeze=7),
               Column("state", no_wrap=True),
               Column("tries", drop=5, justify="right"),
               Column("lag", no_wrap=True, justify="right"),
               Column("last error", drop=3, cap=20, least=14),
               Column("key", drop=9, no_wrap=True, squeeze=10))
    rows: list[list[Entry]] = [
        [Short(cell(d.rule), cell(render.shorten(d.rule, 10))),
         Short(d.event, d.event.removeprefix("fault_")),
         Short(cell(d.fault_code or "-"), cell(render.shorten(d.fault_code or "-", 12))),
         cell(d.state, _STATE_STYLE.get(d.state, "")), str(d.attempts),
         duration(alerts.lag_ns_of(d, now_ns) / NS_PER_SECOND),
         cell(d.last_error or "-"),
         Short(cell(d.key), cell(render.shorten(d.key, 28)))]
        for d in found]
    return render.fitted(cell(f"{len(found)} deliveries, newest first"), columns, rows, width)


def duration(seconds: float) -> str:
    """``0.35 s``, ``12 s``, ``4.5 min``, ``3.2 h``, ``2.0 d``."""
    if seconds < 10:
        return f"{seconds:.2f} s"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    if seconds < 172_800:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86_400:.1f} d"


def register(app: typer.Typer) -> None:
    app.command("alerts")(alerts_command)
