"""Persistence and indexed reads of the statistics projections (docs/statistics.md)."""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from typing import Any, NamedTuple

from sqlalchemy import Connection, and_, delete, func, or_, select

from faultledger.domain.statistics import CodeTrack, Episode, StatFact, StatsOutput
from faultledger.store import fastpath
from faultledger.store.dialects import upsert, upsert_add
from faultledger.store.schema import (
    checkpoints,
    stat_codes,
    stat_episodes,
    stat_facts,
    stat_minutes,
)

CHECKPOINT = "statistics"
"""Row in ``checkpoints``: the seq the statistics tables include (0 after the upgrade that
created them, so the first open fills them from the whole log)."""
NS_PER_MINUTE = 60 * 1_000_000_000
_FLAGS = ("failed", "passed", "activation", "occurrence", "confirmation", "heal", "clear")
_INSERT_FACT = stat_facts.insert()
_CODE_CHUNK = 500


def _fact_row(fact: StatFact) -> dict[str, Any]:
    return {
        "seq": fact.seq, "at_ns": fact.at_ns, "fault_code": fact.code,
        "source_id": fact.source, "severity": fact.severity, "failed": fact.failed,
        "passed": fact.passed, "activation": fact.activation, "occurrence": fact.occurrence,
        "confirmation": fact.confirmation, "heal": fact.heal, "clear": fact.clear,
        "chatter": fact.chatter,
    }


def _episode_row(episode: Episode) -> dict[str, Any]:
    return {
        "start_seq": episode.start_seq, "fault_code": episode.code,
        "source_id": episode.source, "severity": episode.severity,
        "start_ns": episode.start_ns, "end_seq": episode.end_seq, "end_ns": episode.end_ns,
    }


def _episode(row: Any) -> Episode:
    return Episode(row.start_seq, row.fault_code, row.source_id, row.severity, row.start_ns,
                   row.end_seq, row.end_ns)


def _minute_rows(output: StatsOutput) -> list[dict[str, Any]]:
    """Per-minute increments of one output."""
    sums: dict[int, dict[str, int]] = {}

    def bucket(at_ns: int) -> tuple[int, dict[str, int]]:
        minute = at_ns // NS_PER_MINUTE
        row = sums.get(minute)
        if row is None:
            row = sums[minute] = dict.fromkeys(
                (*_FLAGS, "starts", "start_offset_ns", "ends", "end_offset_ns", "repair_ns"), 0)
        return minute, row

    for fact in output.facts:
        _, row = bucket(fact.at_ns)
        for flag in _FLAGS:
            row[flag] += getattr(fact, flag)
    for episode in output.started:
        minute, row = bucket(episode.start_ns)
        row["starts"] += 1
        row["start_offset_ns"] += episode.start_ns - minute * NS_PER_MINUTE
    for episode in output.ended:
        assert episode.end_ns is not None
        minute, row = bucket(episode.end_ns)
        row["ends"] += 1
        row["end_offset_ns"] += episode.end_ns - minute * NS_PER_MINUTE
        row["repair_ns"] += episode.repair_ns
    return [{"minute": minute, **row} for minute, row in sums.items()]


def _track_row(code: str, track: CodeTrack) -> dict[str, Any]:
    return {
        "fault_code": code,
        "last_failed": track.last_failed,
        "activations": json.dumps(list(track.activations)),
        "episode_start_seq": None if track.episode is None else track.episode.start_seq,
    }


def save(conn: Connection, output: StatsOutput, seq: int) -> None:
    """Write one output and move the statistics checkpoint, in the caller's transaction."""
    dialect = conn.dialect.name
    fastpath.execute_many(conn, _INSERT_FACT, [_fact_row(f) for f in output.facts])
    episodes = {e.start_seq: e for e in output.started}
    episodes.update((e.start_seq, e) for e in output.ended)
    fastpath.execute_many(conn, upsert(stat_episodes, dialect),
                          [_episode_row(e) for e in episodes.values()])
    fastpath.execute_many(conn, upsert_add(stat_minutes, dialect), _minute_rows(output))
    fastpath.execute_many(conn, upsert(stat_codes, dialect),
                          [_track_row(code, t) for code, t in output.tracks.items()])
    fastpath.execute_many(conn, upsert(checkpoints, dialect),
                          [{"name": CHECKPOINT, "seq": seq, "hash": "", "policy_seq": 0}])


def replace_all(conn: Connection, output: StatsOutput, seq: int) -> None:
    """Drop the statistics and write a full replay's output (``rebuild``, upgrade)."""
    for table in (stat_facts, stat_episodes, stat_minutes, stat_codes):
        conn.execute(delete(table))
    save(conn, output, seq)


def checkpoint_seq(conn: Connection) -> int:
    row = conn.execute(select(checkpoints.c.seq).where(checkpoints.c.name == CHECKPOINT)).first()
    return 0 if row is None else int(row.seq)


def load_tracks(conn: Connection) -> dict[str, CodeTrack]:
    query = select(stat_codes, stat_episodes).join_from(
        stat_codes, stat_episodes,
        stat_episodes.c.start_seq == stat_codes.c.episode_start_seq, isouter=True)
    tracks: dict[str, CodeTrack] = {}
    for row in conn.execute(query):
        episode = None if row.start_seq is None else _episode(row)
        tracks[row.fault_code] = CodeTrack(bool(row.last_failed),
                                           tuple(json.loads(row.activations)), episode)
    return tracks


# -- reads -------------------------------------------------------------------------------------
class MinuteSums(NamedTuple):
    minute: int
    failed: int
    passed: int
    activation: int
    occurrence: int
    confirmation: int
    heal: int
    clear: int
    starts: int
    start_offset_ns: int
    ends: int
    end_offset_ns: int
    repair_ns: int


def minutes(conn: Connection, first: int, last: int) -> list[MinuteSums]:
    """Per-minute sums for minutes [first, last)."""
    query = (select(stat_minutes)
             .where(stat_minutes.c.minute >= first, stat_minutes.c.minute < last)
             .order_by(stat_minutes.c.minute))
    return [MinuteSums(*row) for row in conn.execute(query)]


def closed_open_at(conn: Connection, at_ns: int) -> int:
    """Ended episodes that were CONFIRMED at ``at_ns`` (start < at <= end)."""
    query = select(func.count()).select_from(stat_episodes).where(
        stat_episodes.c.start_ns < at_ns, stat_episodes.c.end_ns >= at_ns)
    return int(conn.execute(query).scalar_one())


def open_episodes(conn: Connection) -> list[Episode]:
    query = select(stat_episodes).where(stat_episodes.c.end_ns.is_(None))
    return [_episode(row) for row in conn.execute(query)]


def long_episodes(conn: Connection, since_ns: int, until_ns: int, min_ns: int) -> list[Episode]:
    """Ended episodes of at least ``min_ns`` that end after ``since_ns`` and start before
    ``until_ns - min_ns`` (the stale candidates; the partial index holds only long ones)."""
    query = select(stat_episodes).where(
        stat_episodes.c.end_ns - stat_episodes.c.start_ns >= min_ns,
        stat_episodes.c.end_ns > since_ns,
        stat_episodes.c.start_ns < until_ns - min_ns,
    )
    return [_episode(row) for row in conn.execute(query)]


def flagged(conn: Connection, flag: str, since_ns: int, until_ns: int) -> list[tuple[int, str]]:
    """(at_ns, code) of facts with ``flag`` (chatter, confirmation) in [since, until)."""
    column = stat_facts.c[flag]
    query = select(stat_facts.c.at_ns, stat_facts.c.fault_code).where(
        column == 1, stat_facts.c.at_ns >= since_ns, stat_facts.c.at_ns < until_ns)
    return [(int(at), code) for at, code in conn.execute(query)]


def codes(conn: Connection) -> list[str]:
    """Every code the statistics know (globs are matched against these)."""
    return [row[0] for row in conn.execute(select(stat_codes.c.fault_code))]


def facts(conn: Connection, since_ns: int, until_ns: int,
          only: Sequence[str] | None) -> list[StatFact]:
    """Facts in [since, until), of the codes ``only`` (None: all)."""
    window = and_(stat_facts.c.at_ns >= since_ns, stat_facts.c.at_ns < until_ns)
    found: list[StatFact] = []
    for chunk in _chunks(only):
        query = select(stat_facts).where(window)
        if chunk is not None:
            query = query.where(stat_facts.c.fault_code.in_(chunk))
        found.extend(StatFact(*row) for row in conn.execute(query))
    return found


def episodes(conn: Connection, since_ns: int, until_ns: int,
             only: Sequence[str] | None) -> list[Episode]:
    """Episodes that overlap [since, until) or are still open (the caller ends those)."""
    overlaps = and_(stat_episodes.c.start_ns < until_ns,
                    or_(stat_episodes.c.end_ns.is_(None), stat_episodes.c.end_ns > since_ns))
    found: list[Episode] = []
    for chunk in _chunks(only):
        query = select(stat_episodes).where(overlaps)
        if chunk is not None:
            query = query.where(stat_episodes.c.fault_code.in_(chunk))
        found.extend(_episode(row) for row in conn.execute(query))
    return found


def _chunks(only: Sequence[str] | None) -> Iterable[Sequence[str] | None]:
    if only is None:
        yield None
        return
    for start in range(0, len(only), _CODE_CHUNK):
        yield only[start:start + _CODE_CHUNK]
