"""Restoring a ledger's state on open (persisted projections plus a replay of the log tail),
and the replay that ``rebuild``, ``verify`` and ``state_at`` share."""

from __future__ import annotations

import contextlib
import gc
import logging
from collections.abc import Iterable, Iterator

from sqlalchemy import Connection

from faultledger.domain.events import LogRecord
from faultledger.domain.policy import Policy
from faultledger.domain.projector import Projector, Transition
from faultledger.domain.statistics import StatsFold
from faultledger.errors import FaultLedgerError, clipped
from faultledger.store import event_log, projections, stat_tables
from faultledger.store.database import Database

log = logging.getLogger(__name__)

DAMAGED = "its content is damaged or was edited"


class UnreadableRecord(Exception):
    """A stored record this code cannot decode or apply: a damaged or edited payload (valid
    records never fail a replay), named by its seq."""

    def __init__(self, seq: int, error: BaseException) -> None:
        super().__init__(f"record seq {seq} cannot be read back ({clipped(error, 200)})")
        self.seq = seq


@contextlib.contextmanager
def _no_gc_pauses() -> Iterator[None]:
    """A replay allocates several small objects per record (records, faults, facts) and frees
    few: Python's cycle collector then walks the whole growing heap again and again, a
    quarter of a 100,000-record rebuild (docs/performance.md). The records hold no cycles,
    so the collector is paused for the replay and runs as usual afterwards."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def apply_all(projector: Projector, records: Iterable[LogRecord]) -> list[Transition]:
    """``projector.apply_all`` over consecutive records; a record that cannot be decoded (in
    the store's read) or applied raises UnreadableRecord with its seq. Database errors
    (locked, I/O) pass unchanged."""
    reading = iter(records)

    def checked() -> Iterator[LogRecord]:
        while True:
            try:
                record = next(reading)
            except StopIteration:
                return
            except FaultLedgerError:
                raise
            except Exception as error:  # decoding the next record failed
                raise UnreadableRecord(projector.seq + 1, error) from error
            yield record

    try:
        with _no_gc_pauses():
            return projector.apply_all(checked())
    except (UnreadableRecord, FaultLedgerError):
        raise
    except Exception as error:  # applying the record projector.seq failed
        raise UnreadableRecord(projector.seq, error) from error
    finally:
        close = getattr(reading, "close", None)
        if close is not None:  # a streamed read ends before anything else runs on its connection
            close()


def replay(conn: Connection, upto: int | None = None) -> tuple[Projector, list[Transition]]:
    """A fresh projector (with statistics) over the log up to ``upto``, and its transitions."""
    projector = Projector(stats=StatsFold())
    return projector, apply_all(projector, event_log.read_to_end(conn, upto_seq=upto))


def stats_of(projector: Projector) -> StatsFold:
    assert projector.stats is not None, "this projector feeds no statistics"
    return projector.stats


def _saved(conn: Connection) -> tuple[Projector, int]:
    """A projector holding the saved projections (at their checkpoint), and the seq the
    saved statistics include: the projector's statistics fold is theirs only when that
    seq is the checkpoint's."""
    checkpoint = projections.load_checkpoint(conn)
    policy = event_log.policy_at(conn, checkpoint.policy_seq)
    stats_seq = stat_tables.checkpoint_seq(conn)
    tracks = stat_tables.load_tracks(conn) if stats_seq == checkpoint.seq else None
    identity, identity_seq = projections.load_identity(conn) or (None, 0)
    projector = Projector(
        projections.load_faults(conn),
        Policy.model_validate(policy.policy) if policy else None,
        checkpoint.seq,
        policy_recorded=policy is not None,
        policy_seq=checkpoint.policy_seq,
        stats=StatsFold(tracks),
        identity=identity,
        identity_seq=identity_seq,
    )
    return projector, stats_seq


def restore(db: Database) -> tuple[Projector, int, int]:
    """Persisted projections plus a replay of the records after their checkpoint: the
    projector, the log's head seq and how many records were replayed."""
    with db.reading() as conn:
        projector, stats_seq = _saved(conn)
        stored_seq = event_log.head(conn)[0]
    saved = projector.seq
    if stats_seq != saved:
        try:
            projector.stats = catch_up_statistics(db, saved, stats_seq)
        except _Moved:
            return restore(db)
    if stored_seq < saved:
        log.warning("the log ends at seq %d but the projections include seq %d: records were "
                    "deleted; writes are refused (run `faultledger verify`)", stored_seq, saved)
    replayed = max(0, stored_seq - saved)
    if replayed:
        try:
            projector = persist_tail(db, projector)
        except _Moved:  # another process saved them first: start from what it saved
            return restore(db)
    return projector, stored_seq, replayed


def saved_seq(conn: Connection) -> int:
    """How far the saved projections and statistics both go (behind the log's head: a
    process stored records without projecting them, e.g. a fleet central, service/fleet.py)."""
    return min(projections.load_checkpoint(conn).seq, stat_tables.checkpoint_seq(conn))


class _Moved(Exception):
    """The projections moved between reading them and taking the write lock."""


def persist_tail(db: Database, projector: Projector) -> Projector:
    """Bring lagging projections up to the log (in memory, and on disk when writable).

    Several processes opening one log at once all find the same lagging projections; the
    first to take the write lock saves them, the others (``_Moved``) restore again from what
    it saved, rather than saving the same rows twice."""
    try:
        with db.writing() as conn:
            if projections.load_checkpoint(conn).seq != projector.seq:
                raise _Moved
            projector.stage()
            _save_tail(conn, projector)
        projector.commit()
    except FaultLedgerError as error:
        projector.rollback()
        log.warning("projections lag the log and cannot be saved (%s); replaying in memory",
                    error)
        with db.reading() as conn:
            apply_all(projector, event_log.read_to_end(conn, after_seq=projector.seq))
        stats_of(projector).take()
    return projector


def _save_tail(conn: Connection, projector: Projector) -> None:
    """Apply the records after ``projector``'s seq (it holds the saved projections, staged)
    and save what they changed, in the caller's write transaction."""
    identified = projector.identity is not None
    whole = projector.seq == 0  # nothing saved yet (a new schema): a bulk load
    found = apply_all(projector, event_log.read_to_end(conn, after_seq=projector.seq))
    with (projections.loading(conn) if whole else contextlib.nullcontext()):
        projections.save(conn, projector.staged_faults(), found,
                         projections.Checkpoint(*event_log.head(conn), projector.policy_seq))
    if not identified and projector.identity is not None:
        projections.save_identity(conn, projector.identity, projector.identity_seq)
    with (stat_tables.loading(conn) if whole else contextlib.nullcontext()):
        stat_tables.save(conn, stats_of(projector).take(), projector.seq)


def persist_lagging(conn: Connection) -> None:
    """In the caller's write transaction, bring the saved projections and statistics up to
    the log's head from what is saved: for a writer whose own unsaved changes cannot be
    used because another process saved part of them (service/writer.py, "Saving the
    projections")."""
    projector, stats_seq = _saved(conn)
    if stats_seq == projector.seq:
        projector.stage()
        _save_tail(conn, projector)
        return
    save_replay(conn)  # statistics saved to another seq: all of it again


def save_replay(conn: Connection) -> Projector:
    """In the caller's write transaction, replace the saved projections, statistics and
    identity with a full replay of the log (``rebuild``); returns the replay's projector."""
    with _no_gc_pauses():
        replayed, transitions = replay(conn)
        projections.replace_all(conn, replayed.committed(), transitions, projections.Checkpoint(
            *event_log.head(conn), replayed.policy_seq))
        stat_tables.replace_all(conn, stats_of(replayed).take(), replayed.seq)
        projections.replace_identity(conn, replayed.identity, replayed.identity_seq)
    return replayed


def catch_up_statistics(db: Database, upto: int, stats_seq: int) -> StatsFold:
    """Statistics tables behind the projections (first open after the upgrade that created
    them): fold the log up to the projections' seq and write them all."""
    with db.reading() as conn:
        replayed = Projector(stats=StatsFold())
        apply_all(replayed, event_log.read_to_end(conn, upto_seq=upto))
    fold = stats_of(replayed)
    output = fold.take()
    log.info("statistics include seq %d of %d: computing them from the log", stats_seq, upto)
    try:
        with db.writing() as conn:
            if stat_tables.checkpoint_seq(conn) != stats_seq:
                raise _Moved  # another process did it: restore from what it saved
            stat_tables.replace_all(conn, output, upto)
    except FaultLedgerError as error:
        log.warning("statistics cannot be saved (%s); they are incomplete until a writer "
                    "opens this database", error)
    return StatsFold(fold.tracks())
