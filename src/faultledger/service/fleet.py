"""The central's side of store and forward (docs/fleet.md): take a robot's batch of records,
check it, keep it in that robot log's own copy; say how far behind each robot is; read a
robot's logs back.

Each robot log the central receives is kept as a faultledger log of its own (store/fleet_log.py:
a PostgreSQL schema, or a SQLite file beside the central's): records verbatim, projections and
statistics as the robot computes them. So everything the central says about a robot is
computed by the same code over the same records as on the robot, figure for figure.

A batch is checked whole before anything is stored (domain/fleet.py: every hash, the chain
inside it, the identity), then under the log's write lock against what it holds: a record
held already must be the same (then it is ignored: a batch sent again after a lost answer),
the first new one must continue the log. Logs of different robots are written concurrently
(one write lock per log). The answer goes out once the records are committed; the log's
projections follow behind (service/fleet_backlog.py), and every read that needs them brings
them up first.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Iterable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from datetime import datetime

from sqlalchemy import Connection

from faultledger.domain.clock import NS_PER_SECOND, from_ns, to_ns
from faultledger.domain.fault import Fault
from faultledger.domain.fleet import (
    MAX_BATCH_RECORDS,
    BatchError,
    PushedRecord,
    check_batch,
    ledger_id_error,
    robot_id_error,
)
from faultledger.domain.fleet_stats import FLEET_KEYS, merge
from faultledger.domain.identity import LedgerIdentity
from faultledger.domain.stat_rows import StatsRow
from faultledger.errors import FaultLedgerError, InvalidInputError
from faultledger.service import audit, fleet_backlog, restore, statistics
from faultledger.service.ledger import FaultLedger
from faultledger.service.results import VerifyReport
from faultledger.store import event_log, fleet_log
from faultledger.store.database import Database
from faultledger.store.event_log import StoredRecord

__all__ = ["MAX_BATCH_RECORDS", "MAX_HASH_PAGE", "ChainStatus", "Fleet", "PushAnswer",
           "PushBatch", "RobotFault"]

log = logging.getLogger(__name__)

MAX_HASH_PAGE = 10_000
STATS_THREADS = 4
"""Robot logs whose statistics are computed at once (a central's statistics per robot): while
one waits for PostgreSQL the others are folded or queried (20 robots: 378 ms with 2, 311 ms
with 4; bench/fleet.py)."""
OPEN_LOGS = 32
"""Robot logs a central keeps open at once (each holds a database connection for its
writer); more are opened and closed as they are used."""


@dataclass(frozen=True, slots=True)
class PushBatch:
    robot_id: str
    ledger_id: str
    head_seq: int
    records: Sequence[PushedRecord]


@dataclass(frozen=True, slots=True)
class PushAnswer:
    robot_id: str
    ledger_id: str
    last_seq: int
    last_hash: str
    stored: int
    ignored: int


@dataclass(frozen=True, slots=True)
class Stored:
    """What storing a batch did: how far the log now goes, or why nothing was stored
    (``refused``: a docs/fleet.md error code, with the seq it names)."""

    last_seq: int
    last_hash: str
    stored: int = 0
    ignored: int = 0
    refused: str | None = None
    message: str = ""
    seq: int | None = None


@dataclass(frozen=True, slots=True)
class ChainStatus:
    """One robot log as the central holds it (``GET /api/v1/fleet/robots``)."""

    robot_id: str
    ledger_id: str
    last_seq: int
    last_hash: str
    records: int
    last_pushed_at: datetime
    lag_seconds: float
    complete_until: datetime | None
    """The central holds every record the robot wrote up to here (None: nothing yet)."""
    lag_records: int
    """Records the robot had and the central lacked at the robot's last contact."""


@dataclass(frozen=True, slots=True)
class RobotFault:
    robot_id: str
    ledger_id: str
    fault: Fault


@dataclass(frozen=True, slots=True)
class ChainCheck:
    robot_id: str
    ledger_id: str
    report: VerifyReport


def directory_lock_key(ledger_id: str) -> int:
    """A 64-bit advisory lock key per log for its row in the directory."""
    return int.from_bytes(hashlib.sha256(f"fleet:{ledger_id}".encode()).digest()[:8], "big",
                          signed=True)


def lag_ns(chain: fleet_log.Chain, now_ns: int) -> int:
    """now − the time up to which the central holds the robot's whole log (docs/fleet.md,
    "Lag"); from the first contact while it holds nothing yet."""
    return max(0, now_ns - (chain.complete_until_ns or chain.first_contact_ns))


class _Open:
    def __init__(self, ledger: FaultLedger) -> None:
        self.ledger = ledger
        self.users = 0


class Fleet:
    """A central's robot logs: pushes in, status and reads out. Thread-safe; ``close`` it."""

    def __init__(self, central: FaultLedger, open_logs: int = OPEN_LOGS, *,
                 quiet: float = fleet_backlog.QUIET_SECONDS,
                 max_lag: int = fleet_backlog.MAX_LAG) -> None:
        self.central = central
        self._open_logs = open_logs
        self._logs: OrderedDict[int, _Open] = OrderedDict()
        self._lock = threading.Lock()
        self._opening: dict[int, threading.Lock] = {}
        self._databases: dict[int, Database] = {}
        self._known: dict[int, fleet_log.Chain] = {}
        self._entered: dict[str, fleet_log.Chain] = {}
        self._schema: str | None = None
        self._backlog = fleet_backlog.Backlog(self._project, self._lagging, quiet, max_lag)

    def close(self) -> None:
        self._backlog.close()
        with self._lock:
            logs, self._logs = list(self._logs.values()), OrderedDict()
            databases, self._databases = list(self._databases.values()), {}
        for held in logs:
            held.ledger.close()
        for db in databases:
            db.dispose()

    def __enter__(self) -> Fleet:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    # -- the logs ----------------------------------------------------------------------------
    @contextlib.contextmanager
    def log(self, chain: fleet_log.Chain) -> Iterator[FaultLedger]:
        """The robot log of ``chain``, open while the caller uses it, with every record
        acknowledged so far projected."""
        self._backlog.current(chain.chain_id)
        with self._opened(chain) as ledger:
            ledger.catch_up()
            yield ledger

    @contextlib.contextmanager
    def _opened(self, chain: fleet_log.Chain) -> Iterator[FaultLedger]:
        with self._lock:
            held = self._logs.get(chain.chain_id)
            if held is not None:
                self._logs.move_to_end(chain.chain_id)
                held.users += 1
            opening = self._opening.setdefault(chain.chain_id, threading.Lock())
        if held is None:
            with opening:  # one thread opens (and migrates) a log; the others wait for it
                with self._lock:
                    held = self._logs.get(chain.chain_id)
                    if held is not None:
                        held.users += 1
                if held is None:
                    url = fleet_log.chain_url(self.central.url, chain.chain_id)
                    ledger = FaultLedger.open(url, background=False,
                                              database=self._database(chain))
                    with self._lock:
                        held = self._logs[chain.chain_id] = _Open(ledger)
                        held.users += 1
                    self._evict()
        try:
            yield held.ledger
        finally:
            with self._lock:
                held.users -= 1
            self._evict()

    def _database(self, chain: fleet_log.Chain) -> Database:
        """Where a robot log lives: on PostgreSQL its schema, through the central's own pool
        (no engine or connection of its own); on SQLite its own file."""
        url = fleet_log.chain_url(self.central.url, chain.chain_id)
        if self.central._db.dialect == "postgresql":
            return Database.within(self.central._db, url, fleet_log.schema(chain.chain_id))
        return Database(url)

    def _db(self, chain: fleet_log.Chain) -> Database:
        """A robot log's database for work that needs no ledger (storing records,
        projecting, statistics), kept for the next use."""
        with self._lock:
            found = self._databases.get(chain.chain_id)
        if found is not None:
            return found
        made = self._database(chain)
        with self._lock:
            found = self._databases.setdefault(chain.chain_id, made)
        if found is not made:
            made.dispose()
        return found

    def _migrated(self, chain: fleet_log.Chain) -> Database:
        """``_db`` once the log's tables are this version's (opened once in this process,
        which migrates it): before anything is written into it."""
        with self._lock:
            done = chain.chain_id in self._known
        if not done:
            with self._opened(chain):
                pass
            with self._lock:
                self._known[chain.chain_id] = chain
        return self._db(chain)

    def _project(self, chain_id: int) -> None:
        """Bring a log's saved projections and statistics up to its records."""
        with self._lock:
            chain = self._known.get(chain_id)
        if chain is None:
            chain = next((c for c in self.chains() if c.chain_id == chain_id), None)
            if chain is None:
                return
        restore.restore(self._migrated(chain))

    def _lagging(self) -> list[int]:
        """Logs whose records go past their saved projections (the central stopped before
        projecting them)."""
        found = []
        for chain in self.chains():
            try:
                with self._db(chain).reading() as conn:
                    if restore.saved_seq(conn) < event_log.head(conn)[0]:
                        found.append(chain.chain_id)
            except FaultLedgerError as error:  # entered, never written: nothing to project
                log.info("robot log %s: %s", chain.ledger_id, error)
        return found

    def behind(self) -> dict[str, int]:
        """Records per robot log (ledger_id) stored but not yet projected."""
        lag = self._backlog.behind()
        return {c.ledger_id: lag[c.chain_id] for c in self.chains() if c.chain_id in lag}

    def _evict(self) -> None:
        """Close the least recently used idle logs beyond ``open_logs``."""
        closing: list[_Open] = []
        with self._lock:
            for chain_id in list(self._logs):
                if len(self._logs) - len(closing) <= self._open_logs:
                    break
                if self._logs[chain_id].users == 0:
                    closing.append(self._logs.pop(chain_id))
        for held in closing:
            held.ledger.close()

    def _chain(self, ledger_id: str) -> fleet_log.Chain | None:
        with self.central._db.reading() as conn:
            return fleet_log.chain_of(conn, ledger_id)

    def chains(self, robot_id: str | None = None) -> list[fleet_log.Chain]:
        with self.central._db.reading() as conn:
            return fleet_log.chains(conn, robot_id)

    # -- pushes ------------------------------------------------------------------------------
    def push(self, batch: PushBatch, now_ns: int | None = None) -> PushAnswer:
        """Store a robot's batch (BatchError: refused, nothing stored)."""
        for problem in (robot_id_error(batch.robot_id), ledger_id_error(batch.ledger_id)):
            if problem:
                raise BatchError("invalid-request", problem)
        records = tuple(batch.records)
        if records and batch.head_seq < records[-1].seq:
            raise BatchError("invalid-request", f"head_seq {batch.head_seq} is before the "
                             f"batch's last record {records[-1].seq}")
        check_batch(records, batch.robot_id, batch.ledger_id)
        chain = self._entry(batch, now_ns)
        if chain.robot_id != batch.robot_id:
            held = self._chain(batch.ledger_id) or chain
            raise BatchError("robot-differs", f"log {batch.ledger_id} belongs to robot "
                             f"{chain.robot_id}, not {batch.robot_id}", last_seq=held.last_seq)
        done = self._store(chain, batch, records, now_ns)
        if done.refused is not None:
            raise BatchError(done.refused, done.message, done.seq, done.last_seq)
        self._backlog.stored(chain.chain_id, done.stored)
        return PushAnswer(batch.robot_id, batch.ledger_id, done.last_seq, done.last_hash,
                          done.stored, done.ignored)

    def _entry(self, batch: PushBatch, now_ns: int | None) -> fleet_log.Chain:
        """The directory's entry of the batch's log (made at first contact); which robot a
        log belongs to never changes, so it is looked up once per process."""
        with self._lock:
            found = self._entered.get(batch.ledger_id)
        if found is None:
            found = self._chain(batch.ledger_id) or self._enter(batch, now_ns)
            with self._lock:
                self._entered[batch.ledger_id] = found
        return found

    def _store(self, chain: fleet_log.Chain, batch: PushBatch,
               records: Sequence[PushedRecord], now_ns: int | None) -> Stored:
        """Append what the log lacks and note the robot's contact: on PostgreSQL in one
        transaction (the directory is named by the central's schema), on SQLite (the log is
        a file of its own) right after the log's commit; should that fail, the next push
        puts the directory right."""
        schema = self._central_schema()
        with self._migrated(chain).writing() as conn:
            done = self._append(conn, records)
            if schema is not None:
                self._contact(conn, chain, batch, records, done, now_ns, schema)
        if schema is None:
            with self.central._db.writing(
                    lock_key=directory_lock_key(batch.ledger_id)) as conn:
                self._contact(conn, chain, batch, records, done, now_ns, None)
        return done

    def _central_schema(self) -> str | None:
        """The PostgreSQL schema of the central's own tables (None on SQLite)."""
        if self.central._db.dialect != "postgresql":
            return None
        if self._schema is None:
            with self.central._db.reading() as conn:
                self._schema = fleet_log.current_schema(conn)
        return self._schema

    @staticmethod
    def _append(conn: Connection, records: Sequence[PushedRecord]) -> Stored:
        """Under the log's write lock: check the batch against the log's head and append the
        records it lacks, verbatim; a refusal stores nothing."""
        head_seq, head_hash = event_log.head(conn)
        held = [r for r in records if r.seq <= head_seq]
        if held:
            stored = event_log.hashes_between(conn, held[0].seq, held[-1].seq)
            for record in held:
                if stored.get(record.seq) != record.hash:
                    return Stored(head_seq, head_hash, refused="record-differs",
                                  seq=record.seq, message=f"record {record.seq} differs "
                                  "from the one the central holds: the robot's log was "
                                  "rewritten")
        new = records[len(held):]
        if new and new[0].seq != head_seq + 1:
            return Stored(head_seq, head_hash, refused="chain-gap", seq=new[0].seq,
                          message=f"the central holds this log up to seq {head_seq}; the "
                          f"batch starts at {new[0].seq}")
        if new and new[0].prev_hash != head_hash:
            return Stored(head_seq, head_hash, refused="record-differs", seq=head_seq,
                          message=f"record {head_seq} differs from the one the central "
                          "holds (the next record does not chain to it): the robot's log "
                          "was rewritten")
        if not new:
            return Stored(head_seq, head_hash, 0, len(held))
        event_log.append_verbatim(conn, new)
        return Stored(new[-1].seq, new[-1].hash, len(new), len(held))

    def _enter(self, batch: PushBatch, now_ns: int | None) -> fleet_log.Chain:
        with self.central._db.writing(lock_key=directory_lock_key(batch.ledger_id)) as conn:
            found = fleet_log.chain_of(conn, batch.ledger_id)
            if found is None:
                now = time.time_ns() if now_ns is None else now_ns
                found = fleet_log.new_chain(conn, batch.ledger_id, batch.robot_id, now)
        return found

    @staticmethod
    def _contact(conn: Connection, chain: fleet_log.Chain, batch: PushBatch,
                 records: Sequence[PushedRecord], done: Stored, now_ns: int | None,
                 schema: str | None) -> None:
        """Note the robot's contact and how far the log now goes (a refusal too)."""
        last_recorded = 0 if done.refused is not None else max(
            [r.recorded_at_ns for r in records if r.seq <= done.last_seq], default=0)
        fleet_log.record_contact(
            conn, chain.chain_id, last_seq=done.last_seq, last_hash=done.last_hash,
            head_seq=max(batch.head_seq, done.last_seq), last_recorded_ns=last_recorded,
            now_ns=time.time_ns() if now_ns is None else now_ns, schema=schema)

    # -- reads -------------------------------------------------------------------------------
    def robots(self, now_ns: int | None = None, robot_id: str | None = None
               ) -> list[ChainStatus]:
        """Every robot log the central holds (of one robot), with its lag at ``now``."""
        now = time.time_ns() if now_ns is None else now_ns
        return [ChainStatus(
            c.robot_id, c.ledger_id, c.last_seq, c.last_hash, c.last_seq,
            from_ns(c.last_contact_ns),
            round(lag_ns(c, now) / NS_PER_SECOND, 3),
            from_ns(c.complete_until_ns) if c.complete_until_ns else None,
            max(0, c.head_seq - c.last_seq)) for c in self.chains(robot_id)]

    def chain_hashes(self, ledger_id: str, after_seq: int, limit: int
                     ) -> tuple[str, list[tuple[int, str]], int]:
        """(robot_id, a page of (seq, hash) after ``after_seq``, the last seq held) of one
        log; BatchError ``unknown-ledger`` when the central holds nothing of it."""
        problem = ledger_id_error(ledger_id)
        if problem:
            raise BatchError("invalid-request", problem)
        chain = self._chain(ledger_id)
        if chain is None:
            raise BatchError("unknown-ledger", f"the central holds no log {ledger_id}")
        with self.log(chain) as ledger:
            page = [(r.seq, r.hash) for r in audit.export_history(
                ledger, from_seq=after_seq + 1, limit=max(1, min(limit, MAX_HASH_PAGE)))]
            return chain.robot_id, page, ledger.last_seq

    def chains_of(self, robot_id: str, ledger_id: str | None = None) -> list[fleet_log.Chain]:
        """The logs of one robot (the one with ``ledger_id``); InvalidInputError naming what
        the central holds when there is none."""
        problem = robot_id_error(robot_id) or (None if ledger_id is None
                                               else ledger_id_error(ledger_id))
        if problem:
            raise InvalidInputError(problem)
        found = [c for c in self.chains(robot_id)
                 if ledger_id is None or c.ledger_id == ledger_id]
        if not found:
            known = sorted({c.robot_id for c in self.chains()})
            what = f"robot {robot_id}" + ("" if ledger_id is None else f" log {ledger_id}")
            raise InvalidInputError(
                f"the central holds no {what}; it holds "
                + (", ".join(known[:20]) + ("…" if len(known) > 20 else "") if known
                   else "no robot logs (robots push with `faultledger sync`)"))
        return found

    def history(self, robot_id: str, ledger_id: str | None = None, *,
                code: str | None = None, since: datetime | int | None = None,
                until: datetime | int | None = None, source: str | None = None,
                kinds: Iterable[str] = (), limit: int | None = None,
                codes: Sequence[str] | None = None, from_seq: int | None = None,
                to_seq: int | None = None) -> Iterator[tuple[LedgerIdentity, StoredRecord]]:
        """A robot's records as the central holds them, log after log (oldest first), each
        exactly as the robot's own history export gives it, with the log's identity. The
        filters are ``history``'s; ``limit`` applies per log."""
        for chain in self.chains_of(robot_id, ledger_id):
            identity = LedgerIdentity(chain.robot_id, chain.ledger_id)
            with self.log(chain) as ledger:
                rows = audit.export_history(ledger, code, since, until, source, kinds, limit,
                                            codes=codes, from_seq=from_seq, to_seq=to_seq)
                for row in rows:
                    yield identity, row

    def faults(self, robot_id: str | None = None, statuses: Iterable[str] = (),
               severity: int | None = None) -> list[RobotFault]:
        """Faults per (robot, fault code), as each robot's log gives them (``list`` on the
        robot), of every robot or one; a robot with a replaced database shows the faults of
        each of its logs (``ledger_id`` tells them apart)."""
        chains = self.chains_of(robot_id) if robot_id is not None else self.chains()
        found: list[RobotFault] = []
        for chain in chains:
            with self.log(chain) as ledger:
                found.extend(RobotFault(chain.robot_id, chain.ledger_id, fault)
                             for fault in ledger.list_faults(statuses, severity))
        return found

    def stats(self, by: str = "shift", since: datetime | str | None = None,
              until: datetime | str | None = None, codes: Sequence[str] | None = None,
              group_by: Sequence[str] = (), *, robot: str | None = None,
              labels: Mapping[str, Mapping[str, str]] | None = None,
              as_of: datetime | None = None,
              budget: statistics.StatsBudget | None = None) -> list[StatsRow]:
        """Statistics of the robots' logs (of one ``robot``), with the central's calendar
        and e-stop codes: per robot, line or site (``group_by`` robot/line/site, from the
        config's ``fleet.robots`` labels) and the log's own keys. Every row says whether it
        is ``complete``: False while a robot in it has not pushed past the period's end."""
        wanted = (group_by,) if isinstance(group_by, str) else tuple(group_by)
        fleet_keys = [key for key in wanted if key in FLEET_KEYS]
        log_keys = [key for key in wanted if key not in FLEET_KEYS]
        labels = labels or {}
        chains = self.chains_of(robot) if robot is not None else self.chains()
        if not chains:
            raise InvalidInputError(
                f"group_by {', '.join(fleet_keys)} needs a fleet central: this database holds "
                "no robot logs (robots push theirs with `faultledger sync`)")
        several: dict[str, int] = {}
        for chain in chains:
            several[chain.robot_id] = several.get(chain.robot_id, 0) + 1
        groups: list[tuple[dict[str, str | int], dict[str, str | int]]] = []
        for chain in chains:
            robot_labels = labels.get(chain.robot_id, {})
            fleet_group: dict[str, str | int] = {
                "robot": chain.robot_id, "line": robot_labels.get("line", ""),
                "site": robot_labels.get("site", "")}
            replaced: dict[str, str | int] = {}
            if "robot" in fleet_keys and several[chain.robot_id] > 1:
                replaced["ledger_id"] = chain.ledger_id  # a replaced database: never merged
            groups.append(({k: fleet_group[k] for k in fleet_keys}, replaced))
        query = statistics.StatsQuery(by, since, until, codes, log_keys, self.central.calendar,
                                      as_of, self.central.estop_codes, budget)
        merged: dict[tuple[object, ...], list[StatsRow]] = {}
        ranks: dict[tuple[object, ...], tuple[object, ...]] = {}
        order: list[tuple[object, ...]] = []
        for rows in self._compute(chains, groups, query):
            for row in rows:
                key = (row.period.id, row.period.start, *sorted(row.group.items()))
                found = merged.get(key)
                if found is None:
                    merged[key] = found = []
                    order.append(key)
                    ranks[key] = (row.period.start, *(str(value) for value in row.group.values()))
                found.append(row)
        order.sort(key=ranks.__getitem__)  # periods in time order, then the group's values
        return [merge(merged[key], merged[key][0].group) for key in order]

    def _compute(self, chains: Sequence[fleet_log.Chain],
                 groups: Sequence[tuple[dict[str, str | int], dict[str, str | int]]],
                 query: statistics.StatsQuery) -> list[list[StatsRow]]:
        """Each log's statistics rows, in the log's group (its fleet keys, then the log's
        own keys, then its ledger_id where the robot has several logs) and ``complete`` as
        far as the robot has pushed. On PostgreSQL, where the sums answer, one statement
        per figure reads every log (each in its schema); else log by log, a few at a time
        (while one waits for the database another is folded)."""
        for chain in chains:
            self._migrated(chain)
            self._backlog.current(chain.chain_id)
        if self.central._db.dialect == "postgresql" and statistics.from_sums(query):
            schemas = [fleet_log.schema(chain.chain_id) for chain in chains]
            merged_groups = [{**a, **b} for a, b in groups]
            complete = [chain.complete_until_ns for chain in chains]
            # Two halves at once: the server works on one while the other's rows are folded.
            half = (len(chains) + 1) // 2
            parts = [part for part in (slice(0, half), slice(half, len(chains)))
                     if part.start < part.stop]

            def in_schemas(part: slice) -> list[list[StatsRow]]:
                return statistics.compute_in_schemas(
                    self.central._db, schemas[part], query, merged_groups[part],
                    complete[part])

            with ThreadPoolExecutor(2, thread_name_prefix="faultledger-fleet") as pool:
                return [rows for done in pool.map(in_schemas, parts) for rows in done]

        def compute(chain: fleet_log.Chain,
                    group: tuple[dict[str, str | int], dict[str, str | int]]) -> list[StatsRow]:
            fleet_part, replaced = group
            return [replace(row, group={**fleet_part, **row.group, **replaced},
                            complete=chain.complete_until_ns >= to_ns(row.period.end))
                    for row in statistics.compute(self._db(chain), query)]

        with ThreadPoolExecutor(STATS_THREADS, thread_name_prefix="faultledger-fleet") as pool:
            return list(pool.map(compute, chains, groups))

    def verify(self, robot_id: str, ledger_id: str | None = None) -> list[ChainCheck]:
        """``verify`` of every log of a robot as the central holds it: the hash chain, the
        head, and the projections and statistics equal to a full replay."""
        checks = []
        for chain in self.chains_of(robot_id, ledger_id):
            with self.log(chain) as ledger:
                report = ledger.verify()
            if report.ok and report.head_seq < chain.last_seq:
                report = VerifyReport(False, report.records, report.head_seq,
                                      report.head_hash, report.head_seq + 1,
                                      [f"the log ends at seq {report.head_seq} but the central "
                                       f"recorded holding up to seq {chain.last_seq}: records "
                                       "were deleted"])
            checks.append(ChainCheck(chain.robot_id, chain.ledger_id, report))
        return checks
