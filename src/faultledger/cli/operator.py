"""`faultledger ack`, `shelve` and `unshelve`: the operator's day (docs/semantics.md). Each
is recorded with who (default ``cli:$USER``) and why; exit 1 when the fault's state refuses
it (unknown fault, acknowledging a CLEARED one, unshelving what is not shelved), 2 for bad
input."""

from __future__ import annotations

import getpass
import os
from typing import Annotated

import typer

from faultledger.cli.options import ConfigOption, DbOption, Role, fail, opened, prepare
from faultledger.cli.safe_text import printable
from faultledger.errors import Reason
from faultledger.service.results import OperatorResult

CodeArgument = Annotated[str, typer.Argument(metavar="FAULT_CODE", help="The fault code.")]
ActorOption = Annotated[str | None, typer.Option(
    "--actor", metavar="WHO", help="Who does it (default cli:$USER).")]


def user() -> str:
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return str(os.getuid())


def _answer(result: OperatorResult) -> None:
    if not result.success:
        fail(result.message, 2 if result.reason == Reason.INVALID else 1)
    typer.echo(printable(result.message))


def ack(fault_code: CodeArgument,
        note: Annotated[str, typer.Option(
            "--note", metavar="TEXT", help="What you saw or did, for the shift handover.")] = "",
        actor: ActorOption = None, db: DbOption = None, config: ConfigOption = None) -> None:
    """Acknowledge a fault's current episode (its status stays).

    A new episode (the fault comes back after a clear) needs a new acknowledgement; a second
    acknowledgement of one episode records nothing and says who was first.
    """
    with opened(prepare(db, config, Role.WRITER)) as ledger:
        result = ledger.acknowledge(fault_code, actor or f"cli:{user()}", note)
    _answer(result)


def shelve(fault_code: CodeArgument,
           duration: Annotated[str, typer.Option(
               "--for", metavar="DURATION",
               help="How long: 2h, 90m, 1h30m, 1d (at most 30 days).")],
           reason: Annotated[str, typer.Option(
               "--reason", metavar="TEXT", help="Why it is a known nuisance.")] = "",
           actor: ActorOption = None, db: DbOption = None, config: ConfigOption = None) -> None:
    """Hide a known nuisance from lists and alerts for a while.

    Shelving leaves it out of `list`, the dashboard and alerts. Its status and counts go
    on; `list --shelved` shows it. The serving process records the end when the time is
    up; shelving a shelved fault sets a new end.
    """
    with opened(prepare(db, config, Role.WRITER)) as ledger:
        result = ledger.shelve(fault_code, duration, actor or f"cli:{user()}", reason)
    _answer(result)


def unshelve(fault_code: CodeArgument,
             reason: Annotated[str, typer.Option(
                 "--reason", metavar="TEXT", help="Why, for the audit trail.")] = "",
             actor: ActorOption = None, db: DbOption = None,
             config: ConfigOption = None) -> None:
    """End a fault's shelving now."""
    with opened(prepare(db, config, Role.WRITER)) as ledger:
        result = ledger.unshelve(fault_code, actor or f"cli:{user()}", reason)
    _answer(result)


def register(app: typer.Typer) -> None:
    app.command("ack")(ack)
    app.command("shelve")(shelve)
    app.command("unshelve")(unshelve)
