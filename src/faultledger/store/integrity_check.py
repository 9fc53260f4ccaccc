"""The database's own consistency check (SQLite's ``PRAGMA integrity_check``).

The hash chain proves the *records* are the ones written; it says nothing about the b-trees
that hold them. A flipped byte in an index page leaves every record readable and the chain
intact while queries through that index (by code, by time) silently miss rows. SQLite's check
walks every page, table and index and compares each index with its table.
"""

from __future__ import annotations

from sqlalchemy import Connection, text

MAX_MESSAGES = 5
"""SQLite's first messages quoted in a problem; the check stops after a few more."""


def storage_damage(conn: Connection) -> list[str]:
    """Problems SQLite finds in the file (empty: intact, or not SQLite, which has no such check).

    Reads every page: the cost grows with the file (about a second per few hundred MB).
    """
    if conn.dialect.name != "sqlite":
        return []
    rows = conn.execute(text(f"PRAGMA integrity_check({MAX_MESSAGES + 1})")).fetchall()
    messages = [str(row[0]) for row in rows]
    if messages == ["ok"]:
        return []
    shown = "; ".join(messages[:MAX_MESSAGES])
    more = " (and more)" if len(messages) > MAX_MESSAGES else ""
    return [f"SQLite's integrity check found damage in the database file: {shown}{more}"]
