"""What every `faultledger` command shares: the options (`--db`, `--config`, `--shifts`,
`--json`, `--wide`), the one time grammar (docs/cli.md, "Times") and the ledger opener, built
on ``service.bootstrap`` (the one place a ledger is built from configuration).

Errors of the operator's making are one line on stderr and exit 2, also when the app runs
without cli.main's wrapper (tests, embedding).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path
from typing import Annotated, NoReturn

import typer

from faultledger.cli import render
from faultledger.domain.shifts import ShiftCalendar
from faultledger.errors import DamagedDatabaseError, FaultLedgerError
from faultledger.service import times
from faultledger.service.bootstrap import LedgerConfig, Role, open_ledger, resolve
from faultledger.service.config import Settings, config_path, load_settings
from faultledger.service.ledger import FaultLedger
from faultledger.service.policy_check import config_warnings

__all__ = [
    "HELP_MARKUP",
    "ConfigOption",
    "DbOption",
    "JsonOption",
    "LedgerConfig",
    "RobotOption",
    "Role",
    "ShiftsOption",
    "WideOption",
    "fail",
    "opened",
    "parse_moment",
    "parse_time",
    "prepare",
    "settings_for",
]

HELP_MARKUP = None
"""`--help` as click formats it: paragraphs rewrapped to the terminal (docstring line breaks
do not survive, ``\\b`` keeps a block as written), a flag shows no type, an option its metavar
(``--db URL|PATH``). Rich panels kept every docstring line break and showed ``<bool>`` for
every flag (docs/cli.md, "Help")."""

DbOption = Annotated[
    str | None,
    typer.Option("--db", envvar="FAULTLEDGER_DB", show_envvar=True, metavar="URL|PATH",
                 help="Database URL or a plain SQLite file path (default: the config's, else "
                 "sqlite:///var/faultledger.db)."),
]
ConfigOption = Annotated[
    Path | None,
    typer.Option("--config", envvar="FAULTLEDGER_CONFIG", show_envvar=True, metavar="FILE",
                 help="YAML configuration file (default: config/faultledger.yaml when it "
                 "exists in the working directory, else the built-in defaults)."),
]
ShiftsOption = Annotated[
    Path | None,
    typer.Option("--shifts", metavar="FILE",
                 help="Shift calendar YAML (see config/shifts.yaml): shift ids and "
                 "the zone of naive times. Default: the config's `shifts`, else UTC "
                 "morning/afternoon/night from 06:00."),
]
JsonOption = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]
WideOption = Annotated[bool, typer.Option(
    "--wide", help="Show every column, however wide the terminal (default: columns that do "
    "not fit are left out, least important first).")]

TIME_HELP = ("a shift id (2026-11-21/night), a date (2026-11-21) or a date-time "
             "(2026-11-21T22:00, in the calendar's zone unless it has Z or an offset); "
             "see docs/cli.md, Times")
"""The time grammar in one phrase, for `--help` texts."""


RobotOption = Annotated[str | None, typer.Option(
    "--robot", metavar="NAME",
    help="On a fleet central: that robot's logs, as the robot itself gives them.")]


def fail(message: str, code: int = 2) -> NoReturn:
    """One line on stderr and a non-zero exit."""
    render.complain("error:", message)
    raise typer.Exit(code)


def settings_for(config: Path | None) -> Settings:
    try:
        return load_settings(config_path(config))
    except FaultLedgerError as error:
        fail(str(error))


def prepare(db: str | None, config: Path | None, role: Role = Role.READER, *,
            shifts: Path | None = None) -> LedgerConfig:
    """The command's ledger configuration (database URL, policy, calendar) by the precedence
    of docs/configuration.md; a bad config, calendar or database URL is exit 2. A writer that
    records the config's policy warns of its conflicts on stderr (docs/configuration.md,
    "Explaining the policy")."""
    try:
        resolved = resolve(load_settings(config_path(config)), role, db=db, shifts=shifts,
                           config_given=config is not None)
    except FaultLedgerError as error:
        fail(str(error))
    if role is Role.WRITER and resolved.policy is not None:
        # The command records the config's policy: say where it makes a code's thresholds
        # depend on the reporting source (serving processes warn when they open the ledger).
        for warning in config_warnings(resolved.policy):
            render.warn(warning)
    return resolved


@contextmanager
def opened(config: LedgerConfig, *, verifying: bool = False) -> Iterator[FaultLedger]:
    """The ledger for one command: a reader never creates, migrates or records anything.
    For `verify`, a database whose content cannot be read back is a failed check (exit 1)."""
    try:
        ledger = open_ledger(config)
    except DamagedDatabaseError as error:
        if verifying:
            render.complain("verify FAILED:", str(error))
            raise typer.Exit(1) from None
        fail(str(error))
    except FaultLedgerError as error:
        fail(str(error))
    try:
        yield ledger
    except FaultLedgerError as error:
        fail(str(error))
    finally:
        ledger.close()


def parse_time(text: str | None, name: str, calendar: ShiftCalendar, *,
               upper: bool = False, expected: str = times.EXPECTED_TIME) -> datetime | None:
    """``service.times.parse_time`` (the one time grammar); bad input is exit 2."""
    try:
        return times.parse_time(text, name, calendar, upper=upper, expected=expected)
    except FaultLedgerError as error:
        fail(str(error))


def parse_moment(text: str, name: str, calendar: ShiftCalendar) -> datetime | int:
    """``service.times.parse_moment``: a seq number or a time; bad input is exit 2."""
    try:
        return times.parse_moment(text, name, calendar)
    except FaultLedgerError as error:
        fail(str(error))
