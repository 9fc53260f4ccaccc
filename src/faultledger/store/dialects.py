"""The few statements that differ between SQLite and PostgreSQL, kept in one place."""

from __future__ import annotations

from functools import lru_cache
from typing import Any

from sqlalchemy import Table
from sqlalchemy.dialects import postgresql, sqlite


@lru_cache(maxsize=16)
def upsert(table: Table, dialect_name: str) -> Any:
    """INSERT ... ON CONFLICT (primary key) DO UPDATE SET every other column (executemany).

    Built once per table and dialect: constructing SQLAlchemy statements costs more than
    executing them on the ingest path.
    """
    module: Any = postgresql if dialect_name == "postgresql" else sqlite
    statement = module.insert(table)
    keys = [c.name for c in table.primary_key.columns]
    return statement.on_conflict_do_update(
        index_elements=keys,
        set_={c.name: statement.excluded[c.name] for c in table.columns if c.name not in keys},
    )


@lru_cache(maxsize=16)
def upsert_add(table: Table, dialect_name: str) -> Any:
    """INSERT ... ON CONFLICT (primary key) DO UPDATE SET column = column + new value."""
    module: Any = postgresql if dialect_name == "postgresql" else sqlite
    statement = module.insert(table)
    keys = [c.name for c in table.primary_key.columns]
    return statement.on_conflict_do_update(
        index_elements=keys,
        set_={c.name: table.c[c.name] + statement.excluded[c.name]
              for c in table.columns if c.name not in keys},
    )
