"""Schema revisions through Alembic: check, upgrade, and refuse databases from the future."""

from __future__ import annotations

import os
import threading
from functools import lru_cache
from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory

from faultledger.errors import SchemaOutdatedError, SchemaTooNewError, StoreError
from faultledger.store.database import Database, describe, translate_errors


def migrations_dir() -> Path:
    """The package's ``faultledger/migrations/`` (in the wheel too), or $FAULTLEDGER_MIGRATIONS."""
    override = os.environ.get("FAULTLEDGER_MIGRATIONS")
    path = Path(override) if override else Path(__file__).resolve().parents[1] / "migrations"
    if not (path / "env.py").is_file():
        raise StoreError(f"Alembic migrations not found at {path}; set FAULTLEDGER_MIGRATIONS")
    return path


@lru_cache(maxsize=1)
def _scripts() -> ScriptDirectory:
    return ScriptDirectory(str(migrations_dir()))


def head_revision() -> str:
    head = _scripts().get_current_head()
    assert head is not None
    return head


def current_revision(db: Database) -> str | None:
    with translate_errors(db.url), db.engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()


def checked_revision(db: Database) -> str | None:
    """The database's revision; SchemaTooNewError when this code does not know it."""
    current = current_revision(db)
    if current is not None and current not in {s.revision for s in _scripts().walk_revisions()}:
        raise SchemaTooNewError(
            f"database {describe(db.url)} is at schema revision {current!r}, newer than this "
            f"faultledger knows (head {head_revision()!r}); upgrade faultledger"
        )
    return current


_IN_THIS_PROCESS = threading.Lock()
"""Alembic keeps the running migration in module globals (``alembic.op``, ``context``): two
threads migrating two databases at once (a fleet central opening two new robot logs)
would run each other's operations. One migration at a time per process."""


def ensure_current(db: Database, upgrade: bool = True) -> str:
    """Bring the schema to head (or refuse, with ``upgrade=False``); returns the head revision.

    Processes that start together on a new PostgreSQL database take turns (the dialect's
    migration lock): the first creates the schema, the others find it current.
    """
    current = checked_revision(db)
    head = head_revision()
    if current == head:
        return head
    if not upgrade:
        raise SchemaOutdatedError(
            f"database {describe(db.url)} is at schema revision {current!r}, head is {head!r}; "
            "run `faultledger db upgrade`"
        )
    config = Config()
    config.set_main_option("script_location", str(migrations_dir()))
    with _IN_THIS_PROCESS, translate_errors(db.url), db.engine.connect() as raw, \
            db.rules.migration_lock(raw):
        # SQLite: the whole upgrade in one write transaction (BEGIN IMMEDIATE), so processes
        # opening a new file together wait for the first instead of failing "locked".
        conn = raw.execution_options(faultledger_write=True) if db.dialect == "sqlite" else raw
        if MigrationContext.configure(conn).get_current_revision() != head:
            config.attributes["connection"] = conn
            command.upgrade(config, "head")
        conn.commit()
    return head
