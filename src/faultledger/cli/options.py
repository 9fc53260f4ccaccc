"""What every `faultledger` command shares: the options (`--db`, `--config`, `--shifts`,
`--json`, `--wide`), the one time grammar (docs/cli.md, "Times") and the ledger opener, built
on ``service.bootstrap`` (the one place a ledger is built from configuration).

Errors of the operator's making are one line on stderr and exit 2, also when the app runs
without cli.main's wrapper (tests, embedding).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path
from typing import Annotated, NoReturn

import typer

from faultledger.cli import render
from faultledger.domain import validation
from faultledger.domain.periods import parse_bound
from faultledger.domain.shifts import ShiftCalendar
from faultledger.errors import DamagedDatabaseError, FaultLedgerError
from faultledger.service.bootstrap import LedgerConfig, Role, open_ledger, resolve
from faultledger.service.config import Settings, load_settings
from faultledger.service.ledger import FaultLedger

__all__ = ["ConfigOption", "DbOption", "JsonOption", "LedgerConfig", "Role", "ShiftsOption",
           "WideOption", "fail", "opened", "parse_moment", "parse_time", "prepare",
           "settings_for"]

DbOption = Annotated[
    str | None,
    typer.Option("--db", envvar="FAULTLEDGER_DB", show_envvar=True,
                 help="Database URL or a plain SQLite file path (default: the config's, else "
                 "sqlite:///var/faultledger.db)."),
]
ConfigOption = Annotated[
    Path | None,
    typer.Option("--config", envvar="FAULTLEDGER_CONFIG", show_envvar=True,
                 help="YAML configuration file (see config/faultledger.yaml)."),
]
ShiftsOption = Annotated[
    Path | None,
    typer.Option("--shifts", help="Shift calendar YAML (see config/shifts.yaml): shift ids and "
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

SEQ_NUMBER = re.compile(r"[0-9]{1,19}")
"""A seq number where a time or a seq may be given (ASCII digits that fit 64 bits)."""

_EXAMPLES = "(e.g. 2026-11-21, 2026-11-21T22:00, 2026-11-21T22:00Z or 2026-11-21/night)"


def fail(message: str, code: int = 2) -> NoReturn:
    """One line on stderr and a non-zero exit."""
    render.complain("error:", message)
    raise typer.Exit(code)


def settings_for(config: Path | None) -> Settings:
    try:
        return load_settings(config)
    except FaultLedgerError as error:
        fail(str(error))


def prepare(db: str | None, config: Path | None, role: Role = Role.READER, *,
            shifts: Path | None = None) -> LedgerConfig:
    """The command's ledger configuration (database URL, policy, calendar) by the precedence
    of docs/configuration.md; a bad config, calendar or database URL is exit 2."""
    try:
        return resolve(load_settings(config), role, db=db, shifts=shifts,
                       config_given=config is not None)
    except FaultLedgerError as error:
        fail(str(error))


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
               upper: bool = False, expected: str = "an ISO 8601 date or time, or a shift id"
               ) -> datetime | None:
    """The one time grammar (docs/cli.md, "Times"): a shift id (its start; its end when
    ``upper``), an ISO date (local midnight in the calendar's zone) or an ISO date-time (in
    the calendar's zone when naive; an explicit offset or Z is honoured). The result is
    timezone-aware and within the times the log can hold."""
    if text is None:
        return None
    value = text.strip()
    try:
        moment = parse_bound(value, calendar, upper=upper)
    except ValueError as error:
        if "outside the times" in str(error):
            fail(validation.range_message(name, validation.shown(text)))
        if "/" in value:
            fail(f"{name}: {error}")
        fail(f"{name} must be {expected} {_EXAMPLES}, got {validation.shown(text)}")
    problem = validation.time_error(name, moment)
    if problem:
        fail(problem)
    return moment


def parse_moment(text: str, name: str, calendar: ShiftCalendar) -> datetime | int:
    """A seq number (ASCII digits) or a time (``parse_time``): `list --at`, `state-at`."""
    if SEQ_NUMBER.fullmatch(text.strip()):
        return int(text.strip())
    moment = parse_time(text, name, calendar,
                        expected="a seq number or an ISO 8601 date or time, or a shift id")
    assert moment is not None
    return moment
