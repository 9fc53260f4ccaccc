"""`faultledger` commands. Each one parses, calls the FaultLedger API, and renders."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Annotated

import typer

from faultledger.cli import alerts as alert_commands
from faultledger.cli import anchor as anchor_commands
from faultledger.cli import audit, render
from faultledger.cli import fleet as fleet_commands
from faultledger.cli import operator as operator_commands
from faultledger.cli import policy as policy_commands
from faultledger.cli import stats as stats_commands
from faultledger.cli import web as web_commands
from faultledger.cli.options import (
    HELP_MARKUP,
    TIME_HELP,
    ConfigOption,
    DbOption,
    JsonOption,
    LedgerConfig,
    RobotOption,
    Role,
    ShiftsOption,
    WideOption,
    fail,
    opened,
    parse_moment,
    parse_time,
    prepare,
    settings_for,
)
from faultledger.cli.safe_text import cell, printable
from faultledger.domain.clock import from_ns
from faultledger.domain.types import FaultStatus, Severity
from faultledger.errors import FaultLedgerError
from faultledger.service.fleet import Fleet
from faultledger.store import migrate
from faultledger.store.database import Database, describe
from faultledger.version import version

app = typer.Typer(
    help="Event-sourced fault manager: durable fault log, DEM debounce, audit history.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=HELP_MARKUP,
)
db_app = typer.Typer(help="Schema migrations (Alembic).", no_args_is_help=True,
                     rich_markup_mode=HELP_MARKUP)
app.add_typer(db_app, name="db")

STATUSES = ", ".join(s.value for s in FaultStatus)


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"faultledger {version()}")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: Annotated[bool, typer.Option(
        "--version", callback=_print_version, is_eager=True,
        help="Print the faultledger version and exit.")] = False,
) -> None:
    """Event-sourced fault manager: durable fault log, DEM debounce, audit history."""


def url_for(db: str | None, config: Path | None) -> str:
    """The database URL of the commands that do not open a ledger (db, demo)."""
    return prepare(db, config, Role.WRITER).url


def parse_severity(text: str) -> int:
    upper = text.strip().upper()
    if upper in Severity.__members__:
        return int(Severity[upper])
    try:
        return int(text)
    except ValueError:
        fail(f"severity must be 0-3 or INFO/WARN/ERROR/CRITICAL, got {text!r}")


@app.command()
def report(
    fault_code: Annotated[str, typer.Argument(metavar="FAULT_CODE",
                                              help="Fault code, e.g. MOTOR_OVERHEAT.")],
    event_type: Annotated[str, typer.Argument(metavar="EVENT_TYPE",
                                              help="FAILED or PASSED (or 0/1).")],
    severity: Annotated[str, typer.Option("--severity", "-s", metavar="LEVEL",
                                          help="0-3 or INFO/WARN/ERROR/CRITICAL.")] = "ERROR",
    description: Annotated[str, typer.Option("--description", "-d", metavar="TEXT",
                                             help="What happened, for people.")] = "",
    source: Annotated[str, typer.Option("--source", metavar="ID",
                                        help="Reporting source id.")] = "/cli",
    at: Annotated[str | None, typer.Option(
        "--at", metavar="TIME", help=f"When it happened: {TIME_HELP}. Default: now.")] = None,
    shifts: ShiftsOption = None,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """Record one FAILED or PASSED report."""
    setup = prepare(db, config, Role.WRITER, shifts=shifts)
    moment = parse_time(at, "--at", setup.calendar)
    with opened(setup) as ledger:
        result = ledger.report(fault_code, event_type, parse_severity(severity), description,
                               source, moment)
        if not result.accepted:
            fail(f"report rejected: {result.message}", 1)
        fault = ledger.get_fault(fault_code)
    status = fault.status.value if fault else "(no fault)"
    typer.echo(printable(f"accepted: {result.message}; {fault_code} is {status}"))


@app.command("list")
def list_faults(
    status: Annotated[list[str] | None, typer.Option(
        "--status", metavar="STATUS",
        help="Status to include (repeatable). Default: CONFIRMED.")] = None,
    all_statuses: Annotated[bool, typer.Option("--all", help="Every status.")] = False,
    severity: Annotated[str | None, typer.Option(
        "--severity", "-s", metavar="LEVEL",
        help="Only this severity: 0-3 or INFO/WARN/ERROR/CRITICAL.")] = None,
    shelved: Annotated[bool, typer.Option(
        "--shelved", help="Only the shelved faults (hidden otherwise).")] = False,
    at: Annotated[str | None, typer.Option(
        "--at", metavar="SEQ|TIME",
        help=f"The table (every status) as the ledger knew it after a seq number, or after "
        f"the records recorded by a time (by recording time, like state-at): {TIME_HELP}.")
    ] = None,
    as_json: JsonOption = False,
    wide: WideOption = False,
    robot: RobotOption = None,
    shifts: ShiftsOption = None,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """List the faults: CONFIRMED ones unless --status/--all say.

    Unacknowledged faults first; shelved ones are left out (--shelved lists only them).
    --at shows the table of an earlier seq or time (every fault, as the log then held it).
    """
    for name in status or []:
        if name.strip().upper() not in FaultStatus.__members__:
            fail(f"unknown status {printable(name)!r}; valid statuses: {STATUSES}")
    setup = prepare(db, config, shifts=shifts)
    calendar = setup.calendar
    moment = None if at is None else parse_moment(at, "--at", calendar)
    notes: list[str] = []
    if robot is not None:
        if moment is not None:
            fail("--at and --robot do not combine: --at reads this log's own records")
        _list_robot(setup, robot, status, all_statuses, severity, as_json, wide)
        return
    with opened(setup) as ledger:
        if moment is not None:
            prefix = audit.log_prefix(ledger, moment, calendar)
            faults, title, notes = prefix.faults, prefix.title, prefix.notes
        else:
            statuses = ([s.value for s in FaultStatus] if all_statuses
                        else [name.strip().upper() for name in status or []])
            wanted_severity = None if severity is None else parse_severity(severity)
            faults = ledger.triage(statuses, wanted_severity, "only" if shelved else "hide")
            title = f"{'shelved ' if shelved else ''}faults in {describe(ledger.url)}"
    if as_json:
        typer.echo(json.dumps([render.fault_dict(f) for f in faults], indent=2))
    else:
        out = render.console(wide=wide)
        out.print(render.faults_table(faults, title, calendar, render.fit_width(out, wide)))
    for note in notes:
        render.note(note)


def _list_robot(setup: LedgerConfig, robot: str, status: list[str] | None, all_statuses: bool,
                severity: str | None, as_json: bool, wide: bool) -> None:
    """``list --robot``: a robot's faults as a fleet central holds its logs (a table per
    log; JSON items carry robot_id and ledger_id)."""
    statuses = ([s.value for s in FaultStatus] if all_statuses
                else [name.strip().upper() for name in status or []])
    wanted_severity = None if severity is None else parse_severity(severity)
    with opened(setup) as central, Fleet(central) as robot_logs:
        try:
            found = robot_logs.faults(robot, statuses, wanted_severity)
            chains = robot_logs.chains_of(robot)
        except FaultLedgerError as error:
            fail(str(error))
    if as_json:
        typer.echo(json.dumps([{"robot_id": item.robot_id, "ledger_id": item.ledger_id,
                                **render.fault_dict(item.fault)} for item in found], indent=2))
        return
    out = render.console(wide=wide)
    for chain in chains:
        faults = [item.fault for item in found if item.ledger_id == chain.ledger_id]
        out.print(render.faults_table(faults, f"faults of robot {chain.robot_id}, log "
                                      f"{chain.ledger_id}", setup.calendar,
                                      render.fit_width(out, wide)))


@app.command()
def show(
    fault_code: Annotated[str, typer.Argument(metavar="FAULT_CODE", help="The fault code.")],
    as_json: JsonOption = False,
    wide: WideOption = False,
    shifts: ShiftsOption = None,
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """Show one fault: episode, acknowledgement, transitions.

    Its shelving and last clear too. Any status, also CLEARED; the first occurrence ever
    and the current episode's start; who acknowledged and who cleared it last, and why.
    """
    setup = prepare(db, config, shifts=shifts)
    calendar = setup.calendar
    with opened(setup) as ledger:
        lookup = ledger.lookup_fault(fault_code)
        if lookup.fault is None:
            fail(lookup.message, 1)
        moves = ledger.transitions(fault_code)
        clears = ledger.history(code=fault_code, kinds=("fault_cleared",))
    reasons = {r.seq: str(r.payload.get("reason", "")) for r in clears}
    last = clears[-1] if clears else None
    cleared = None if last is None else {
        "seq": last.seq, "at": render.when(last.occurred_at),
        "by": str(last.payload.get("actor", "")), "reason": reasons[last.seq]}
    if as_json:
        data = render.fault_dict(lookup.fault)
        data["transitions"] = [
            {"seq": t.seq, "at": render.when(from_ns(t.at_ns)),
             "from": t.from_status.value if t.from_status else None,
             "to": t.to_status.value, "cause": t.cause, "by": t.source_id,
             **({"reason": reasons[t.seq]} if t.seq in reasons else {})}
            for t in moves
        ]
        data["last_cleared"] = cleared
        typer.echo(json.dumps(data, indent=2))
        return
    out = render.console(wide=wide)
    width = render.fit_width(out, wide)
    out.print(render.faults_table([lookup.fault], f"fault {fault_code}", calendar, width))
    for line in render.episode_lines(lookup.fault, calendar):
        out.print(cell(line))
    if cleared is not None and last is not None:
        reason = cleared["reason"] or "(no reason given)"
        out.print(cell(f"last cleared {render.zoned(last.occurred_at, calendar)} "
                       f"by {cleared['by']}: {reason}"))
    out.print(render.transitions_table(moves, calendar, width, reasons))


@app.command()
def clear(
    fault_code: Annotated[str, typer.Argument(metavar="FAULT_CODE", help="The fault code.")],
    actor: Annotated[str | None, typer.Option(
        metavar="WHO", help="Who clears (default cli:$USER).")] = None,
    reason: Annotated[str, typer.Option(metavar="TEXT", help="Why, for the audit trail.")] = "",
    db: DbOption = None,
    config: ConfigOption = None,
) -> None:
    """Clear a fault (recorded with who and why)."""
    who = actor or f"cli:{operator_commands.user()}"
    with opened(prepare(db, config, Role.WRITER)) as ledger:
        result = ledger.clear(fault_code, actor=who, reason=reason)
    if not result.success:
        fail(result.message, 1)
    typer.echo(printable(result.message))


# history, verify and state-at: the audit commands, in cli/audit.py.
audit.register(app)
# stats and report-shift, in cli/stats.py.
stats_commands.register(app)
# anchor (export, keygen): signed anchors of the log head, in cli/anchor.py.
anchor_commands.register(app)
web_commands.register(app)
# sync: push this robot's log to a fleet central, in cli/fleet.py.
fleet_commands.register(app)
# ack, shelve, unshelve: the operator's day, in cli/operator.py.
operator_commands.register(app)
# policy explain: the debounce fields of one report and their rules, in cli/policy.py.
policy_commands.register(app)
# alerts: the alert rules' deliveries, in cli/alerts.py.
alert_commands.register(app)


@app.command()
def rebuild(db: DbOption = None, config: ConfigOption = None) -> None:
    """Drop the projections and replay the whole log."""
    with opened(prepare(db, config, Role.WRITER)) as ledger:
        count = ledger.rebuild()
        faults = len(ledger.all_faults())
    typer.echo(f"rebuilt projections from {count} records: {faults} faults")


@db_app.command("upgrade")
def db_upgrade(db: DbOption = None, config: ConfigOption = None) -> None:
    """Create the database or migrate it to the newest schema revision."""
    database = Database(url_for(db, config))
    try:
        before = migrate.current_revision(database)
        head = migrate.ensure_current(database, upgrade=True)
    finally:
        database.dispose()
    typer.echo(printable(f"{describe(database.url)}: {before or '(empty)'} -> {head}"))


@db_app.command("current")
def db_current(db: DbOption = None, config: ConfigOption = None) -> None:
    """Print the database's schema revision and the newest one this version knows."""
    database = Database(url_for(db, config), create=False)
    try:
        current = migrate.checked_revision(database)
    finally:
        database.dispose()
    head = migrate.head_revision()
    state = "up to date" if current == head else "needs `faultledger db upgrade`"
    typer.echo(printable(
        f"{describe(database.url)}: {current or '(empty)'} (head {head}, {state})"))


@app.command(context_settings={"allow_extra_args": True, "ignore_unknown_options": True})
def serve(
    ctx: typer.Context,
    db: DbOption = None,
    config: ConfigOption = None,
    follower: Annotated[bool, typer.Option(
        "--follower", help="Serve reads only, as /fault_manager_follower, next to a running "
        "/fault_manager on the same database; reports and clears are refused.")] = False,
    http: Annotated[str | None, typer.Option(
        "--http", metavar="[HOST:]PORT",
        help="Also serve the HTTP API and dashboard on [HOST:]PORT (e.g. 8080 or "
        "127.0.0.1:8080; docs/http.md), over the same ledger.")] = None,
) -> None:
    """Run the ROS 2 fault manager node (/fault_manager).

    It serves until SIGINT/SIGTERM, and refuses to start (exit 2) when another fault manager
    already serves the same names. ROS arguments follow, e.g. `--ros-args -p
    confirmation_threshold:=-3`.
    """
    try:
        from faultledger.ros.serve import serve as run_node
    except ImportError as error:
        fail(f"ROS 2 is not installed in this environment ({error}); run `make interfaces`")
    raise typer.Exit(run_node(settings_for(config), db, list(ctx.args), follower=follower,
                              http_listen=http))


@app.command(context_settings={"allow_extra_args": True, "ignore_unknown_options": True})
def bridge(
    ctx: typer.Context,
    name: Annotated[str, typer.Argument(
        metavar="NAME", help="action-status, node-state, hardware-status or diagnostics.")],
    config: Annotated[Path | None, typer.Option(
        "--config", metavar="FILE",
        help="The bridge's YAML settings (see config/<bridge>.yaml).")] = None,
) -> None:
    """Run one bridge as a ROS node of its own.

    It reports to /fault_manager until SIGINT/SIGTERM. ROS arguments follow, e.g.
    `--ros-args -r __ns:=/robot1`.
    """
    try:
        from faultledger.ros.bridges.runner import run_bridge
    except ImportError as error:
        fail(f"ROS 2 is not installed in this environment ({error}); run `make interfaces`")
    raise typer.Exit(run_bridge(name, config, list(ctx.args)))


@app.command(context_settings={"allow_extra_args": True, "ignore_unknown_options": True})
def nodes(
    ctx: typer.Context,
    topic: Annotated[str, typer.Option(
        metavar="TOPIC", help="NodeState topic to listen on.")] = "/nodemon/state",
    once: Annotated[bool, typer.Option(
        "--once", help="Print one snapshot after --listen-sec and exit.")] = False,
    listen_sec: Annotated[float, typer.Option(
        "--listen-sec", min=0.0, metavar="SEC",
        help="With --once: how long to listen first.")] = 2.0,
    sort: Annotated[str, typer.Option(
        "--sort", metavar="KEY", help="name, state (worst first) or age (longest silent first); "
        "key s cycles it.")] = "name",
    name_filter: Annotated[str, typer.Option(
        "--filter", metavar="TEXT",
        help="Only nodes whose name contains this; key f or / sets it.")] = "",
    state: Annotated[list[str] | None, typer.Option(
        "--state", metavar="STATE",
        help="Only nodes in this state (LOST, RUNNING, ERROR...); repeatable.")
    ] = None,
    timeout_sec: Annotated[float, typer.Option(
        "--timeout-sec", min=0.0, metavar="SEC", help="Silence after which a node shows LOST (the "
        "node-state bridge's heartbeat_timeout_sec).")] = 5.0,
) -> None:
    """Live view of every node's nodemon heartbeat.

    State, age, last non-RUNNING state and messages, until q or Ctrl-C. ROS arguments follow,
    e.g. `--ros-args -r __ns:=/robot1`.
    """
    if sort not in ("name", "state", "age"):
        fail(f"--sort must be name, state or age, got {printable(sort)!r}")
    try:
        from faultledger.cli.nodes_view import run_nodes_view
    except ImportError as error:
        fail(f"ROS 2 is not installed in this environment ({error}); run `make interfaces`")
    raise typer.Exit(run_nodes_view(topic, once, listen_sec, list(ctx.args), sort=sort,
                                    name_filter=name_filter, states=state or (),
                                    timeout_sec=timeout_sec))


@app.command()
def demo(
    db: Annotated[str | None, typer.Option(
        "--db", metavar="URL|PATH",
        help="Add the demo's records to this database instead (never a fault manager's live "
        "one). Default: a new scratch SQLite file in the temporary directory, kept so you can "
        "look at it; FAULTLEDGER_DB and the config's database are not used.")] = None,
    wide: WideOption = False,
    shifts: ShiftsOption = None,
    config: ConfigOption = None,
) -> None:
    """A scripted fault life cycle on a scratch database.

    One fault goes PREFAILED -> CONFIRMED -> HEALED -> CLEARED; the notifications, the log and
    the status transitions are shown, and the chain verified.
    """
    from faultledger.cli.demo import run_demo, scratch_database

    scratch, url = (None, db) if db else scratch_database()
    setup = prepare(url, config, Role.WRITER, shifts=shifts)
    out = render.console(wide=wide)
    run_demo(setup.url, out, setup.calendar, render.fit_width(out, wide), scratch,
             setup.robot_id)


def main() -> None:
    """Console entry point: operator errors print one line and exit 2, never a traceback."""
    try:
        app()  # standalone: usage errors print help and exit 2 by themselves
    except FaultLedgerError as error:
        render.complain("error:", str(error))
        sys.exit(2)
    except Exception as error:
        if os.environ.get("FAULTLEDGER_DEBUG"):
            raise
        render.complain("internal error:", f"{type(error).__name__}: {error} "
                        "(set FAULTLEDGER_DEBUG=1 for a traceback)")
        sys.exit(70)


if __name__ == "__main__":
    main()
