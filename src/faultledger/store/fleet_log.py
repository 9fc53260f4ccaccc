"""A fleet central's directory of robot logs, and where each of those logs lives.

The central keeps every robot log it receives as a faultledger log of its own, records
verbatim (the hash covers them byte for byte), with the usual projections and statistics
beside them: on PostgreSQL in a schema of the central's database (``fleet_chain_<n>``), on
SQLite in a file beside the central's (``<central>.fleet/chain-<n>.db``). So a robot's
history, verify, fault list and statistics at the central are computed by the same code
over the same records as on the robot, figure for figure.

``fleet_chains`` says per log (``ledger_id``) which robot it is, how far the central holds it
and when the robot last made contact (docs/fleet.md, "Lag").
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from sqlalchemy import (
    BigInteger,
    Connection,
    MetaData,
    bindparam,
    case,
    insert,
    select,
    text,
    update,
)
from sqlalchemy.engine import make_url

from faultledger.domain.integrity import GENESIS_HASH
from faultledger.store.schema import fleet_chains

SCHEMA_PREFIX = "fleet_chain_"


@dataclass(frozen=True, slots=True)
class Chain:
    chain_id: int
    ledger_id: str
    robot_id: str
    last_seq: int
    last_hash: str
    head_seq: int
    first_contact_ns: int
    last_contact_ns: int
    last_recorded_ns: int
    complete_until_ns: int


def _chain(row: Any) -> Chain:
    return Chain(*(row[i] for i in range(10)))


def chain_of(conn: Connection, ledger_id: str) -> Chain | None:
    row = conn.execute(select(fleet_chains).where(fleet_chains.c.ledger_id == ledger_id)).first()
    return None if row is None else _chain(row)


def chains(conn: Connection, robot_id: str | None = None) -> list[Chain]:
    query = select(fleet_chains).order_by(fleet_chains.c.robot_id,
                                          fleet_chains.c.first_contact_ns,
                                          fleet_chains.c.chain_id)
    if robot_id is not None:
        query = query.where(fleet_chains.c.robot_id == robot_id)
    return [_chain(row) for row in conn.execute(query)]


def new_chain(conn: Connection, ledger_id: str, robot_id: str, now_ns: int) -> Chain:
    """Enter a log in the directory, and make its home (a schema on PostgreSQL)."""
    conn.execute(insert(fleet_chains).values(
        ledger_id=ledger_id, robot_id=robot_id, last_seq=0, last_hash=GENESIS_HASH, head_seq=0,
        first_contact_ns=now_ns, last_contact_ns=now_ns, last_recorded_ns=0,
        complete_until_ns=0))
    found = chain_of(conn, ledger_id)
    assert found is not None
    if conn.dialect.name == "postgresql":
        conn.execute(text(f'CREATE SCHEMA IF NOT EXISTS "{schema(found.chain_id)}"'))
    return found


def current_schema(conn: Connection) -> str:
    """Where a PostgreSQL connection's unqualified tables are (the central's own)."""
    return str(conn.execute(text("SELECT current_schema()")).scalar_one())


def schema(chain_id: int) -> str:
    """The PostgreSQL schema of a robot log."""
    return f"{SCHEMA_PREFIX}{chain_id}"


def chain_url(central_url: str, chain_id: int) -> str:
    """The URL of one robot log the central keeps: an ordinary faultledger database."""
    url = make_url(central_url)
    if url.get_backend_name() == "postgresql":
        options = url.query.get("options")
        kept = " ".join(options) if isinstance(options, tuple) else (options or "")
        words = [w for w in kept.split() if not w.startswith("-csearch_path=")]
        words.append(f"-csearch_path={schema(chain_id)}")
        return url.update_query_dict({"options": " ".join(words)}).render_as_string(
            hide_password=False)
    database = url.database or ""
    if not database or database == ":memory:":
        raise ValueError("a fleet central on SQLite needs a database file")
    path = Path(database)
    return str(url.set(database=str(path.with_name(f"{path.name}.fleet")
                                    / f"chain-{chain_id}.db")))


def record_contact(conn: Connection, chain_id: int, *, last_seq: int, last_hash: str,
                   head_seq: int, last_recorded_ns: int, now_ns: int,
                   schema: str | None = None) -> None:
    """Move the chain's head and note the contact, in one statement (no lock needed): the log
    is complete up to now when the robot has nothing the central lacks, else up to the newest
    record it holds; neither mark ever moves back. ``schema``: the central's, named when the
    connection's search_path is a robot log's (PostgreSQL: the contact is noted in the
    transaction that stores the records)."""
    conn.execute(_contact_statement(schema), {
        "id": chain_id, "seq": last_seq, "hash": last_hash, "head": head_seq,
        "recorded": last_recorded_ns, "now": now_ns})


@lru_cache(maxsize=4)
def _contact_statement(schema: str | None) -> Any:
    """Built once: constructing the statement costs more than running it."""
    table = (fleet_chains if schema is None
             else fleet_chains.to_metadata(MetaData(), schema=schema))
    c = table.c
    seq, head_seq, now = (bindparam(name, type_=BigInteger) for name in ("seq", "head", "now"))
    last_recorded = bindparam("recorded", type_=BigInteger)
    head = case((c.head_seq > head_seq, c.head_seq), else_=head_seq)
    recorded = case((c.last_recorded_ns > last_recorded, c.last_recorded_ns),
                    else_=last_recorded)
    complete = case((seq >= head, now), else_=recorded)
    return update(table).where(c.chain_id == bindparam("id")).values(
        last_seq=seq, last_hash=bindparam("hash"), head_seq=head, last_contact_ns=now,
        last_recorded_ns=recorded,
        complete_until_ns=case((c.complete_until_ns > complete, c.complete_until_ns),
                               else_=complete))
