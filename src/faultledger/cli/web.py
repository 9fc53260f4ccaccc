"""`faultledger http` (the HTTP API and dashboard without ROS) and `faultledger token create`
(`token list` and `token revoke`: cli/tokens.py). Registered by cli/main.py; docs/http.md is
the reference."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from faultledger.cli import render
from faultledger.cli.options import (
    HELP_MARKUP,
    ConfigOption,
    DbOption,
    ShiftsOption,
    fail,
    prepare,
    settings_for,
)
from faultledger.cli.safe_text import printable
from faultledger.cli.tokens import PICKUP, token_file, token_list, token_revoke
from faultledger.errors import FaultLedgerError
from faultledger.service.bootstrap import Role, open_ledger
from faultledger.service.config import TOKEN_NAME_RULE
from faultledger.service.policy_check import startup_warnings
from faultledger.service.tokens import check_name, check_role, issue, parse_lifetime, utc_text
from faultledger.store.database import describe

ListenOption = Annotated[str | None, typer.Option(
    "--listen", metavar="[HOST:]PORT",
    help="[HOST:]PORT to serve on (default: the config's http.listen, "
    "127.0.0.1:8080). Any address but loopback needs tokens.")]

token_app = typer.Typer(help="Bearer tokens of the HTTP API.\n\nOnly their hashes are stored.",
                        no_args_is_help=True, rich_markup_mode=HELP_MARKUP)


def register(app: typer.Typer) -> None:
    app.command("http")(http)
    app.add_typer(token_app, name="token")


def http(listen: ListenOption = None, db: DbOption = None, config: ConfigOption = None,
         shifts: ShiftsOption = None,
         read_only: Annotated[bool, typer.Option(
             "--read-only", help="Serve reads only, beside a fault manager that writes the "
             "same database; reports and clears answer 503.")] = False) -> None:
    """Serve the HTTP API and the dashboard, without ROS.

    Over one database, until Ctrl-C; docs/http.md.
    """
    from faultledger.alerts.deliverer import AlertDeliverer
    from faultledger.fleet.push import PusherThread
    from faultledger.http.server import HttpServer

    settings = settings_for(config)
    ledger_config = prepare(db, config, Role.READER if read_only else Role.SERVER,
                            shifts=shifts)
    try:
        ledger = open_ledger(ledger_config)
    except FaultLedgerError as error:
        fail(str(error))
    pusher: PusherThread | None = None
    deliverer: AlertDeliverer | None = None
    try:
        if not read_only:  # the writer beside a read-only server warns of its own policy
            for warning in startup_warnings(ledger):
                render.warn(warning)
        try:
            server = HttpServer(ledger, settings.http, ledger_config.calendar, listen,
                                read_only=read_only,
                                fleet_labels=settings.fleet.labels() if settings.fleet else None)
        except FaultLedgerError as error:
            fail(str(error))
        # The config's fleet: push this log to a central, as `sync --follow` does (a
        # read-only server writes nothing, so it pushes nothing: its writer does).
        try:
            pusher = None if read_only else PusherThread.start_for(ledger, settings.fleet)
        except FaultLedgerError as error:
            fail(str(error))
        # The config's alerts: delivered by this process (a read-only one delivers nothing:
        # its writer's process does).
        try:
            deliverer = None if read_only else AlertDeliverer.start_for(ledger, settings.alerts)
        except FaultLedgerError as error:
            fail(str(error))
        mode = " (read-only)" if read_only else ""
        typer.echo(printable(f"faultledger http ready{mode}: {server.url} db="
                             f"{describe(ledger_config.url)}; {server.access}; "
                             f"dashboard {server.url}, API {server.url}docs"))
        if pusher is not None:
            typer.echo(printable(pusher.describe))
        if deliverer is not None:
            typer.echo(printable(deliverer.describe))
        server.run()
    finally:
        if deliverer is not None:
            deliverer.stop()
        if pusher is not None:
            pusher.stop()
        ledger.close()


@token_app.command("create")
def token_create(
    name: Annotated[str, typer.Option(
        "--name", metavar="NAME", help="Who holds it; the actor of its changes. "
        f"{TOKEN_NAME_RULE}.")],
    role: Annotated[str, typer.Option(
        "--role", metavar="ROLE",
        help="viewer (reads), reporter (POST reports only), operator (reads, "
        "reports, clears), admin (everything) or robot (pushes the log of the robot "
        "NAME to a fleet central, nothing else).")],
    config: ConfigOption = None,
    file: Annotated[Path | None, typer.Option(
        "--file", metavar="FILE",
        help="Token file to add it to (default: the config's http.tokens_file, "
        "var/http-tokens.yaml).")] = None,
    expires: Annotated[str | None, typer.Option(
        "--expires", metavar="DURATION",
        help="Valid for this long, e.g. 12h or 30d (s, m, h, d); default: "
        "no expiry.")] = None,
) -> None:
    """Issue a token: printed once, only its SHA-256 is stored (file mode 0600).

    A running server accepts it within 2 s.
    """
    settings = settings_for(config)
    try:
        check_name(name)
        token_role = check_role(role)
        lifetime = None if expires is None else parse_lifetime(expires)
    except FaultLedgerError as error:
        fail(str(error))
    path = token_file(settings, file)
    try:
        token, entry = issue(path, name, token_role, lifetime)
    except FaultLedgerError as error:
        fail(str(error))
    typer.echo(token)
    until = ("no expiry" if entry.expires_at is None
             else f"expires {utc_text(entry.expires_at)}")
    typer.echo(printable(f"token {name!r} ({token_role.value}, {until}) added to {path}; it "
                         f"is shown only now; {PICKUP.format('accepts it')}."), err=True)


token_app.command("list")(token_list)
token_app.command("revoke")(token_revoke)
