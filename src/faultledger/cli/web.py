"""`faultledger http` (the HTTP API and dashboard without ROS) and `faultledger token create`.
Registered by cli/main.py; docs/http.md is the reference."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from faultledger.cli.options import (
    ConfigOption,
    DbOption,
    ShiftsOption,
    fail,
    prepare,
    settings_for,
)
from faultledger.cli.safe_text import printable
from faultledger.errors import FaultLedgerError
from faultledger.service.bootstrap import Role, open_ledger
from faultledger.service.tokens import Role as TokenRole
from faultledger.service.tokens import issue
from faultledger.store.database import describe

ListenOption = Annotated[str | None, typer.Option(
    "--listen", help="[HOST:]PORT to serve on (default: the config's http.listen, "
    "127.0.0.1:8080). Any address but loopback needs tokens.")]

token_app = typer.Typer(help="Bearer tokens of the HTTP API (only their hashes are stored).",
                        no_args_is_help=True)


def register(app: typer.Typer) -> None:
    app.command("http")(http)
    app.add_typer(token_app, name="token")


def http(listen: ListenOption = None, db: DbOption = None, config: ConfigOption = None,
         shifts: ShiftsOption = None,
         read_only: Annotated[bool, typer.Option(
             "--read-only", help="Serve reads only, beside a fault manager that writes the "
             "same database; reports and clears answer 503.")] = False) -> None:
    """Serve the HTTP API and the dashboard over a database, without ROS, until Ctrl-C."""
    from faultledger.http.server import HttpServer

    settings = settings_for(config)
    ledger_config = prepare(db, config, Role.READER if read_only else Role.SERVER,
                            shifts=shifts)
    try:
        ledger = open_ledger(ledger_config)
    except FaultLedgerError as error:
        fail(str(error))
    try:
        try:
            server = HttpServer(ledger, settings.http, ledger_config.calendar, listen,
                                read_only=read_only)
        except FaultLedgerError as error:
            fail(str(error))
        mode = " (read-only)" if read_only else ""
        typer.echo(printable(f"faultledger http ready{mode}: {server.url} db="
                             f"{describe(ledger_config.url)}; {server.access}; "
                             f"dashboard {server.url}, API {server.url}docs"))
        server.run()
    finally:
        ledger.close()


@token_app.command("create")
def token_create(
    name: Annotated[str, typer.Option("--name", help="Who holds it; the actor of its changes.")],
    role: Annotated[TokenRole, typer.Option(
        "--role", help="viewer (reads), reporter (POST reports only), operator (reads, "
        "reports, clears) or admin (everything).")],
    config: ConfigOption = None,
    file: Annotated[Path | None, typer.Option(
        "--file", help="Token file to add it to (default: the config's http.tokens_file, "
        "var/http-tokens.yaml).")] = None,
) -> None:
    """Issue a token: printed once, only its SHA-256 is stored (file mode 0600)."""
    settings = settings_for(config)
    path = file or settings.http.tokens_file
    if path is None:
        fail("no token file: give --file or set http.tokens_file in the config")
    try:
        token = issue(path, name, role)
    except FaultLedgerError as error:
        fail(str(error))
    typer.echo(token)
    typer.echo(printable(f"token {name!r} ({role.value}) added to {path}; it is shown only "
                         "now. Restart the server to use it."), err=True)
