"""Schema revisions through Alembic: check, upgrade, and refuse databases from the future."""

from __future__ import annotations

import os
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
    with translate_errors(db.url), db.engine.connect() as conn, db.rules.migration_lock(conn):
        if MigrationContext.configure(conn).get_current_revision() != head:
            config.attributes["connection"] = conn
            command.upgrade(config, "head")
        conn.commit()
    return head
