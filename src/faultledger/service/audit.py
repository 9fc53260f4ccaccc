"""Audit reads: filtered and streamed history, prefixes named by time, and verification of the
log (hash chain, checkpoint, projections against a replay) behind ``FaultLedger.verify``."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import replace
from datetime import datetime
from typing import TYPE_CHECKING

from sqlalchemy import Connection

from faultledger.domain.identity import LedgerIdentity
from faultledger.domain.projector import Projector
from faultledger.errors import FaultLedgerError, InvalidInputError
from faultledger.service.arguments import (
    aware_ns,
    check_seq_range,
    record_filter,
    seq_number,
)
from faultledger.service.restore import DAMAGED, UnreadableRecord, replay, stats_of
from faultledger.service.results import VerifyReport
from faultledger.store import event_log, integrity_check, log_index, projections, stat_tables
from faultledger.store.database import Database

if TYPE_CHECKING:
    from faultledger.service.ledger import FaultLedger


# -- history -------------------------------------------------------------------------------------
def export_history(ledger: FaultLedger, code: str | None = None,
                   since: datetime | int | None = None, until: datetime | int | None = None,
                   source: str | None = None, kinds: Iterable[str] = (),
                   limit: int | None = None, *, codes: Sequence[str] | None = None,
                   from_seq: int | None = None, to_seq: int | None = None,
                   descending: bool = False) -> Iterator[event_log.StoredRecord]:
    """``history``'s selection as stored rows with their predecessor's hash, streamed
    (``descending``: newest first, and ``limit`` keeps the newest).

    For exports of any size: rows are fetched in chunks inside one read transaction while the
    caller consumes them (a consistent snapshot). The filter is checked here, before the
    first row, so bad input fails before anything is written.
    """
    where = record_filter(code, since, until, source, kinds, limit, codes, from_seq, to_seq)
    return _stored_rows(ledger._db, replace(where, descending=descending))


def count_history(ledger: FaultLedger, code: str | None = None,
                  since: datetime | int | None = None, until: datetime | int | None = None,
                  source: str | None = None, kinds: Iterable[str] = (), *,
                  codes: Sequence[str] | None = None, from_seq: int | None = None,
                  to_seq: int | None = None) -> int:
    """How many records ``history`` selects with these filters (no limit)."""
    where = record_filter(code, since, until, source, kinds, None, codes, from_seq, to_seq)
    with ledger._db.reading() as conn:
        return event_log.count_matching(conn, where)


def _stored_rows(db: Database, where: event_log.RecordFilter
                 ) -> Iterator[event_log.StoredRecord]:
    with db.reading() as conn:
        yield from event_log.iter_stored(conn, where)


# -- prefixes by time ----------------------------------------------------------------------------
def seq_recorded_by(ledger: FaultLedger, when: datetime | int) -> int:
    """The last seq of the log prefix ``state_at(when)`` replays, so it can be named and
    verified: a seq is checked against the log, a time maps to the records recorded by it."""
    with ledger._db.reading() as conn:
        if isinstance(when, int):
            when = seq_number(when, "seq")
            head_seq = event_log.head(conn)[0]
            if not 0 <= when <= head_seq:
                raise InvalidInputError(f"seq {when} is not in the log (seq 0..{head_seq})")
            return when
        return event_log.last_seq_recorded_by(conn, aware_ns(when, "when"))


def seqs_recorded_between(ledger: FaultLedger, since: datetime | None,
                          until: datetime | None) -> tuple[int, int | None]:
    """Inclusive seq range of the records recorded in [since, until]: a contiguous segment
    that ``verify`` can check (``occurred_at`` is the reporter's and not in seq order).

    ``until`` ends where ``state_at(until)``'s prefix ends; None means up to the head.
    """
    with ledger._db.reading() as conn:
        start = 1 if since is None else event_log.last_seq_recorded_by(
            conn, aware_ns(since, "since") - 1) + 1
        end = None if until is None else event_log.last_seq_recorded_by(
            conn, aware_ns(until, "until"))
        head_seq = event_log.head(conn)[0]
    if start > (head_seq if end is None else end):
        window = " and ".join(f"{name} {moment.isoformat()}" for name, moment
                              in (("since", since), ("until", until)) if moment is not None)
        raise InvalidInputError(f"no record of the log (seq 1..{head_seq}) was recorded within "
                                f"{window}")
    return start, end


# -- verification --------------------------------------------------------------------------------
def verify(db: Database, from_seq: int | None = None, to_seq: int | None = None
           ) -> VerifyReport:
    """``FaultLedger.verify``: the whole log (with the database's integrity check and a replay
    of the projections), or one segment of the chain; with the log's identity as its
    projection records it (a whole-log check compares that with a replay)."""
    if from_seq is not None or to_seq is not None:
        report = _verify_segment(db, 1 if from_seq is None else from_seq, to_seq)
    else:
        report = _with_storage_damage(db, lambda: _verify_log(db))
    try:
        with db.reading() as conn:
            found = projections.load_identity(conn)
    except FaultLedgerError:
        return report  # the storage problem is the report already
    return report if found is None else replace(report, identity=found[0])


def _verify_log(db: Database) -> VerifyReport:
    with db.reading() as conn:
        chain = event_log.check_chain(conn)
        checkpoint = projections.load_checkpoint(conn)
        problems = [chain.problem] if chain.problem else []
        first_bad = chain.first_bad_seq
        if chain.problem is None:
            if checkpoint.seq > chain.head_seq:
                first_bad = chain.head_seq + 1
                problems.append(
                    f"the log ends at seq {chain.head_seq} but the projections include seq "
                    f"{checkpoint.seq}: records {chain.head_seq + 1}..{checkpoint.seq} were "
                    "deleted")
            elif checkpoint.seq == chain.head_seq and checkpoint.hash != chain.head_hash:
                first_bad = chain.head_seq
                problems.append(f"record {chain.head_seq} differs from the recorded head")
        if not problems:
            try:
                problems.extend(_projection_problems(conn, checkpoint))
            except UnreadableRecord as error:  # its hash matches: rehashed, or written so
                first_bad = error.seq
                problems.append(f"{error}: {DAMAGED} (its hash and those after it match: "
                                "they were recomputed, or it was written so)")
    return VerifyReport(not problems, chain.records, chain.head_seq, chain.head_hash,
                        first_bad, problems)


def _with_storage_damage(db: Database, check: Callable[[], VerifyReport]) -> VerifyReport:
    """``check`` after the database's own integrity check; damage fails the report. A damaged
    file may also break the check itself: then the damage and that error are the report."""
    with db.reading() as conn:
        damage = integrity_check.storage_damage(conn)
    if not damage:
        return check()
    try:
        report = check()
    except Exception as error:  # any failure reading a file known to be damaged
        return VerifyReport(False, 0, 0, "", None,
                            [*damage, f"the log could not be checked: {error}"])
    return VerifyReport(False, report.records, report.head_seq, report.head_hash,
                        report.first_bad_seq, [*damage, *report.problems])


def _verify_segment(db: Database, from_seq: int, to_seq: int | None) -> VerifyReport:
    """``verify`` over [from_seq, to_seq]: the chain segment and the checkpoint inside it."""
    check_seq_range(from_seq, to_seq)
    with db.reading() as conn:
        chain = event_log.check_chain(conn, from_seq, to_seq)
        problems = [chain.problem] if chain.problem else []
        first_bad = chain.first_bad_seq
        if chain.problem is None:
            found = _checkpoint_problem(conn, from_seq, to_seq, chain)
            if found is not None:
                first_bad = found[0]
                problems.append(found[1])
    return VerifyReport(not problems, chain.records, chain.head_seq, chain.head_hash, first_bad,
                        problems)


def _checkpoint_problem(conn: Connection, from_seq: int, to_seq: int | None,
                        chain: event_log.ChainCheck) -> tuple[int, str] | None:
    """The checkpoint names (seq, hash) of a record: it must exist and match when the verified
    segment is open-ended or holds that seq (catches a rewritten head with a fresh hash)."""
    checkpoint = projections.load_checkpoint(conn)
    if to_seq is None and checkpoint.seq > chain.head_seq:
        return chain.head_seq + 1, (
            f"the log ends at seq {chain.head_seq} but the projections include seq "
            f"{checkpoint.seq}: records {chain.head_seq + 1}..{checkpoint.seq} were deleted")
    if (from_seq <= checkpoint.seq <= chain.head_seq
            and event_log.hash_at(conn, checkpoint.seq) != checkpoint.hash):
        return checkpoint.seq, f"record {checkpoint.seq} differs from the recorded head"
    return None


def _projection_problems(conn: Connection, checkpoint: projections.Checkpoint) -> list[str]:
    """Where the persisted projections differ from a full replay up to their checkpoint."""
    expected, expected_transitions = replay(conn, checkpoint.seq)
    stored = projections.load_faults(conn)
    problems: list[str] = []
    replayed = {f.fault_code: f for f in expected.committed()}
    for code in sorted(set(stored) | set(replayed)):
        if stored.get(code) != replayed.get(code):
            problems.append(f"projection of fault {code} differs from a full replay of the log")
    if projections.load_transitions(conn) != expected_transitions:
        problems.append("transitions table differs from a full replay of the log")
    problems.extend(log_index.differences(conn, checkpoint.seq))
    if stat_tables.checkpoint_seq(conn) == checkpoint.seq:
        problems.extend(stat_tables.differences(conn, stats_of(expected).take()))
    else:
        problems.append(f"statistics include seq {stat_tables.checkpoint_seq(conn)}, the "
                        f"projections {checkpoint.seq}")
    if checkpoint.policy_seq != expected.policy_seq:
        problems.append(f"checkpoint names record {checkpoint.policy_seq} as the policy in force, "
                        f"a replay finds {expected.policy_seq}")
    problems.extend(_identity_problems(conn, expected))
    return problems


def _identity_problems(conn: Connection, expected: Projector) -> list[str]:
    """The identity projection against a replay; and any later ``ledger_identified`` record,
    which no writer writes (the first one stays the identity, the others are ignored)."""
    stored = projections.load_identity(conn)
    replayed = (None if expected.identity is None
                else (expected.identity, expected.identity_seq))
    problems = []
    if stored != replayed:
        def shown(found: tuple[LedgerIdentity, int] | None) -> str:
            return "none" if found is None else (
                f"robot_id {found[0].robot_id!r}, ledger_id {found[0].ledger_id} "
                f"(record {found[1]})")
        problems.append(f"the recorded identity ({shown(stored)}) differs from a full replay "
                        f"of the log ({shown(replayed)})")
    problems.extend(f"record {seq} is a second ledger_identified record (the log's identity "
                    f"is record {expected.identity_seq}): no writer writes one; it is ignored"
                    for seq in expected.ignored_identities)
    return problems
