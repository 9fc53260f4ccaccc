"""The one place a ledger is built from configuration, for the CLI, `serve` and `http`.

Precedence, for every entry point alike (docs/configuration.md, "Precedence"):
- database: ``--db`` / ``FAULTLEDGER_DB`` > the ROS parameter ``database_path`` (serve) >
  the config file's ``database.url`` > ``sqlite:///var/faultledger.db``; a plain file path is
  a SQLite file.
- policy: ROS parameters (serve) > the config file's ``policy`` > medkit's defaults; a
  command that only reads never records a policy (the log's own applies).
- shift calendar: ``--shifts`` > the config file's ``shifts`` > the built-in UTC calendar.
- e-stop codes: the config file's ``estop_codes`` > ``HW_*_EMERGENCY_STOP``.
- robot_id: the config file's ``robot_id`` > the host name (for a log without identity); a
  command that only reads opens any robot's log (it records nothing).
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError, NoSuchModuleError

from faultledger.domain.periods import default_calendar
from faultledger.domain.policy import Policy
from faultledger.domain.shifts import ShiftCalendar
from faultledger.domain.stat_rows import DEFAULT_ESTOP_CODES
from faultledger.errors import ConfigError
from faultledger.service.config import Settings, load_shift_calendar
from faultledger.service.ledger import FaultLedger

DRIVERS = {
    "postgresql": ("psycopg", "postgresql"),
    "postgresql+psycopg": ("psycopg", "postgresql"),
}
"""URL scheme -> (module it needs, the faultledger extra that installs it)."""
SUPPORTED = ("sqlite", "postgresql")
"""The databases faultledger runs on (store/dialects.py); any other is refused up front."""


class Role(StrEnum):
    """What an entry point does with the database."""

    READER = "reader"
    """Reads only: never creates, migrates or records anything (list, history, stats…)."""
    WRITER = "writer"
    """One command that writes (report, clear, rebuild): creates and migrates."""
    SERVER = "server"
    """A serving process (serve, http): records its policy, runs the timers."""


@dataclass(frozen=True, slots=True)
class LedgerConfig:
    """Everything ``FaultLedger.open`` needs, resolved from the precedence above."""

    url: str
    policy: Policy | None
    calendar: ShiftCalendar
    max_batch: int
    role: Role
    estop_codes: tuple[str, ...] = DEFAULT_ESTOP_CODES
    robot_id: str | None = None
    """Configured explicitly: a writer refuses a log that records another robot_id."""


def database_url(text: str) -> str:
    """A SQLAlchemy URL, or a plain file path taken as a SQLite file (``var/f.db``,
    ``/data/faults.db``). A URL of a database faultledger does not run on (``mysql://``…),
    or whose driver is not installed (naming the extra to install) or is asyncio-only, is
    refused here, rather than failing later on an import."""
    value = text.strip()
    if not value:
        raise ConfigError("the database URL is empty")
    if "://" not in value:
        return f"sqlite:///{Path(value).expanduser()}"
    try:
        url = make_url(value)
    except ArgumentError as error:
        raise ConfigError(f"invalid database URL {value!r}: {error}") from None
    shown = url.render_as_string(hide_password=True)
    try:
        dialect = url.get_dialect()
    except NoSuchModuleError:
        raise ConfigError(f"unknown database kind {url.drivername!r} in {shown!r}: use "
                          "sqlite:///FILE (or a plain path) or postgresql+psycopg://…") from None
    if url.get_backend_name() not in SUPPORTED:
        raise ConfigError(f"unsupported database {url.get_backend_name()!r} in {shown!r}: "
                          "faultledger runs on SQLite (sqlite:///FILE or a plain path) or "
                          "PostgreSQL (postgresql+psycopg://…)")
    needed = DRIVERS.get(url.drivername)
    if needed is not None and importlib.util.find_spec(needed[0]) is None:
        module, extra = needed
        raise ConfigError(f"database URL {shown!r} needs "
                          f"the {module} driver: pip install 'faultledger[{extra}]'")
    try:
        if getattr(dialect, "is_async", False):
            raise ImportError("an asyncio driver")
        dialect.import_dbapi()
    except ImportError:
        raise ConfigError(f"database URL {shown!r}: the {url.get_driver_name()} driver cannot "
                          "be used (not installed, or asyncio only); use sqlite:///FILE or "
                          "postgresql+psycopg://… (pip install 'faultledger[postgresql]')"
                          ) from None
    return value


def resolve(settings: Settings, role: Role, *, db: str | None = None,
            database_path: str | None = None, policy: Policy | None = None,
            shifts: Path | None = None, config_given: bool = True) -> LedgerConfig:
    """The ledger configuration of one entry point (see the module docstring).

    ``policy`` is the serving process's own (ROS parameters applied); a one-shot writer
    records the config file's policy only when a config file was given, so `report` on a
    database does not silently change the policy a fault manager recorded.
    """
    if db:
        url = database_url(db)
    elif database_path:
        url = database_url(database_path)
    else:
        url = database_url(settings.database.url)
    if role is Role.SERVER:
        chosen: Policy | None = policy or settings.policy
    elif role is Role.WRITER:
        chosen = policy or (settings.policy if config_given else None)
    else:
        chosen = None
    path = shifts or settings.shifts
    calendar = default_calendar() if path is None else load_shift_calendar(path)
    return LedgerConfig(url, chosen, calendar, settings.database.max_batch, role,
                        tuple(settings.estop_codes), settings.robot_id)


def open_ledger(config: LedgerConfig) -> FaultLedger:
    """Open the ledger an entry point asked for; errors are FaultLedgerError subclasses.

    A reader opens without the configured robot_id: it records nothing, so it may read a log
    copied from another robot (verify, history) on a robot that has one configured.
    """
    writes = config.role is not Role.READER
    return FaultLedger.open(config.url, policy=config.policy, max_batch=config.max_batch,
                            create=writes, upgrade=writes,
                            background=config.role is Role.SERVER, calendar=config.calendar,
                            estop_codes=config.estop_codes,
                            robot_id=config.robot_id if writes else None)
