"""Persistence and indexed reads of the statistics projections (docs/statistics.md)."""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from contextlib import AbstractContextManager
from typing import Any

from sqlalchemy import (
    BigInteger,
    Connection,
    Integer,
    and_,
    column,
    delete,
    func,
    literal_column,
    or_,
    select,
    text,
    update,
)
from sqlalchemy import table as table_clause

from faultledger.domain.stat_rows import GOAL_METRIC_OF, GOAL_METRICS
from faultledger.domain.statistics import (
    SHELF,
    CodeTrack,
    Episode,
    GoalFact,
    OperatorFact,
    StatFact,
    StatsOutput,
)
from faultledger.store import fastpath
from faultledger.store.dialects import bulk_load, upsert, upsert_add
from faultledger.store.schema import (
    STAT_FLAGS,
    checkpoints,
    stat_codes,
    stat_episodes,
    stat_facts,
    stat_goals,
    stat_hours,
    stat_minutes,
    stat_operator,
)

CHECKPOINT = "statistics"
"""Row in ``checkpoints``: the seq the statistics tables include (0 after the upgrade that
created them, so the first open fills them from the whole log)."""
NS_PER_MINUTE = 60 * 1_000_000_000
NS_PER_HOUR = 60 * NS_PER_MINUTE
_INSERT_GOAL = stat_goals.insert()
_CODE_CHUNK = 500


_OPERATOR_COLUMNS = ("seq", "kind", "fault_code", "source_id", "severity", "at_ns", "delay_ns",
                     "until_ns", "end_seq", "end_ns")
"""stat_operator's columns in the order of OperatorFact's fields."""
_FACT_COLUMNS = ("seq", "at_ns", "fault_code", "source_id", "severity", *STAT_FLAGS, "chatter")
"""The columns of ``stat_facts``, in the order of StatFact's fields: a fact is its row."""
_FLAG_FIELDS = [StatFact._fields.index(flag) for flag in STAT_FLAGS]


def _goal_row(goal: GoalFact) -> dict[str, Any]:
    return {"seq": goal.seq, "at_ns": goal.at_ns, "action": goal.action,
            "status": goal.status, "server_node": goal.server_node}


def _episode_row(episode: Episode) -> dict[str, Any]:
    return {
        "start_seq": episode.start_seq, "fault_code": episode.code,
        "source_id": episode.source, "severity": episode.severity,
        "start_ns": episode.start_ns, "end_seq": episode.end_seq, "end_ns": episode.end_ns,
    }


def _episode(row: Any) -> Episode:
    return Episode(row.start_seq, row.fault_code, row.source_id, row.severity, row.start_ns,
                   row.end_seq, row.end_ns)


def _flag_sums(facts: Sequence[StatFact]) -> dict[int, list[int]]:
    """Per minute (``at_ns // NS_PER_MINUTE``), the sum of each of STAT_FLAGS over the facts:
    one pass over the facts serves the minute and the hour sums alike."""
    facts_in: dict[int, list[StatFact]] = {}
    for fact in facts:
        facts_in.setdefault(fact.at_ns // NS_PER_MINUTE, []).append(fact)
    sums: dict[int, list[int]] = {}
    for minute, group in facts_in.items():  # a save holds ~1,000 facts: sum columns, not flags
        columns = list(zip(*group, strict=True))
        sums[minute] = [sum(columns[field]) for field in _FLAG_FIELDS]
    return sums


def _sum_rows(output: StatsOutput, flag_sums: dict[int, list[int]], unit_ns: int,
              key: str) -> list[dict[str, Any]]:
    """Per-minute (per-hour) increments of one output: ``key`` is ``at_ns // unit_ns``,
    offsets are within that minute (hour). ``flag_sums``: ``_flag_sums`` of its facts (a
    minute lies within one hour, so an hour's flags are the sum of its minutes')."""
    sums: dict[int, dict[str, int]] = {}

    def bucket(at_ns: int) -> tuple[int, dict[str, int]]:
        unit = at_ns // unit_ns
        row = sums.get(unit)
        if row is None:
            row = sums[unit] = dict.fromkeys(
                (*STAT_FLAGS, "starts", "start_offset_ns", "ends", "end_offset_ns", "repairs",
                 "repair_ns", *GOAL_METRICS), 0)
        return unit, row

    for goal in output.goals:
        _, row = bucket(goal.at_ns)
        row[GOAL_METRIC_OF[goal.status]] += 1
    for minute, flags in flag_sums.items():
        _, row = bucket(minute * NS_PER_MINUTE)
        for flag, value in zip(STAT_FLAGS, flags, strict=True):
            row[flag] += value
    for episode in output.started:
        unit, row = bucket(episode.start_ns)
        row["starts"] += 1
        row["start_offset_ns"] += episode.start_ns - unit * unit_ns
    for episode in output.ended:
        assert episode.end_ns is not None
        stop = episode.stop_ns(episode.end_ns)
        unit, row = bucket(stop)
        row["ends"] += 1
        row["end_offset_ns"] += stop - unit * unit_ns
        _, row = bucket(episode.end_ns)  # the repair counts where its record is
        row["repairs"] += 1
        row["repair_ns"] += episode.repair_ns
    return [{key: unit, **row} for unit, row in sums.items()]


def _minute_and_hour_rows(output: StatsOutput
                          ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The per-minute and per-hour increments of one output, its facts summed once."""
    flags = _flag_sums(output.facts)
    return (_sum_rows(output, flags, NS_PER_MINUTE, "minute"),
            _sum_rows(output, flags, NS_PER_HOUR, "hour"))


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
    fastpath.insert_tuples(conn, stat_facts, _FACT_COLUMNS, output.facts)
    fastpath.execute_many(conn, _INSERT_GOAL, [_goal_row(g) for g in output.goals])
    episodes = {e.start_seq: e for e in output.started}
    episodes.update((e.start_seq, e) for e in output.ended)
    fastpath.execute_many(conn, upsert(stat_episodes, dialect),
                          [_episode_row(e) for e in episodes.values()])
    minutes, hours = _minute_and_hour_rows(output)
    fastpath.execute_many(conn, upsert_add(stat_minutes, dialect), minutes)
    fastpath.execute_many(conn, upsert_add(stat_hours, dialect), hours)
    fastpath.execute_many(conn, upsert(stat_codes, dialect),
                          [_track_row(code, t) for code, t in output.tracks.items()])
    fastpath.insert_tuples(conn, stat_operator, _OPERATOR_COLUMNS, output.operator)
    for start_seq, end_seq, end_ns in output.shelf_ends:  # rare: one statement each
        conn.execute(update(stat_operator).where(stat_operator.c.seq == start_seq)
                     .values(end_seq=end_seq, end_ns=end_ns))
    fastpath.execute_many(conn, upsert(checkpoints, dialect),
                          [{"name": CHECKPOINT, "seq": seq, "hash": "", "policy_seq": 0}])


def replace_all(conn: Connection, output: StatsOutput, seq: int) -> None:
    """Drop the statistics and write a full replay's output (``rebuild``, upgrade)."""
    for table in _TABLES:
        conn.execute(delete(table))
    with loading(conn):
        save(conn, output, seq)


_TABLES = (stat_facts, stat_episodes, stat_minutes, stat_hours, stat_codes, stat_goals,
           stat_operator)


def loading(conn: Connection) -> AbstractContextManager[None]:
    """Around a save that fills emptied statistics (a replay of the whole log)."""
    return bulk_load(conn, _TABLES, appended=(stat_facts,))  # one fact per record


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
def _values(rows: Sequence[tuple[int, int, int]]) -> str:
    """Ranges (i, a, b) as a SQL VALUES list: integer literals (``int()`` makes that safe).
    Bound parameters would hit SQLite's variable limit at ~10,000 periods, and SQLAlchemy
    needs ~0.5 ms per row to compile a VALUES construct."""
    return ",".join(f"({int(i)},{int(a)},{int(b)})" for i, a, b in rows)


def _ranges(rows: Sequence[tuple[int, int, int]], unit: str) -> Any:
    """Ranges (i, a, b) as a table p(i, a, b) to join against (bounds in ``unit``; an i may
    have several ranges), a CTE of the statement."""
    return text(f"SELECT column1 AS i, column2 AS a, column3 AS b FROM (VALUES {_values(rows)}) "
                "AS v").columns(column("i", Integer), column("a", BigInteger),
                                column("b", BigInteger)).cte(f"p_{unit}")


class Logs:
    """Where the statistics reads below look: one log (``conn``'s own tables) or many logs of
    one PostgreSQL database (``schemas``, a fleet central's robot logs: one statement reads
    them all). Each read answers per log, in this order."""

    def __init__(self, conn: Connection, schemas: Sequence[str] | None = None) -> None:
        self.conn = conn
        self.schemas = schemas
        self._shared: dict[str, str] = {}

    def __len__(self) -> int:
        return 1 if self.schemas is None else len(self.schemas)

    def ranges(self, rows: Sequence[tuple[int, int, int]], unit: str) -> Any:
        """``_ranges`` for the next read; over many logs written once for all of them (a
        copy per log would be planned once per log)."""
        if self.schemas is None:
            return _ranges(rows, unit)
        name = f"p_{unit}"
        self._shared[name] = f"{name}(i, a, b) AS MATERIALIZED (VALUES {_values(rows)})"
        return table_clause(name, column("i", Integer), column("a", BigInteger),
                     column("b", BigInteger))

    def periods(self, edges: Sequence[tuple[int, int]], unit: str) -> Any:
        """The periods as a table p(i, a, b) to join against (bounds in ``unit``)."""
        return self.ranges([(i, a, b) for i, (a, b) in enumerate(edges)], unit)

    def rows(self, query: Any) -> list[list[tuple[Any, ...]]]:
        if self.schemas is None:
            return [[tuple(row) for row in self.conn.execute(query)]]
        shared, self._shared = list(self._shared.values()), {}
        return fastpath.fetch_all_in_schemas(self.conn, query, self.schemas, shared)


def period_sums(logs: Logs, minute_edges: Sequence[tuple[int, int]]
                ) -> list[list[tuple[int, ...]]]:
    """Per log, per period i (bounds in whole minutes): i, the seven counts, starts,
    Σ starts·minute, Σ start offsets, ends, Σ ends·minute, Σ end offsets, repairs, Σ repair
    ns, aborted, canceled and succeeded goals. Whole hours are read from ``stat_hours`` (an
    hour's row gives Σ starts·(its first minute) and offsets within the hour: the same
    Σ start ns), the minutes before the first and after the last whole hour from
    ``stat_minutes``."""
    hours: list[tuple[int, int, int]] = []
    minutes: list[tuple[int, int, int]] = []
    for i, (a, b) in enumerate(minute_edges):
        first, last = -(-a // 60), b // 60
        if first < last:
            hours.append((i, first, last))
            minutes.extend((i, x, y) for x, y in ((a, first * 60), (last * 60, b)) if x < y)
        elif a < b:
            minutes.append((i, a, b))
    totals: list[dict[int, list[int]]] = [{} for _ in range(len(logs))]
    for table, key, per_minute, ranges in ((stat_hours, "hour", 60, hours),
                                           (stat_minutes, "minute", 1, minutes)):
        if not ranges:
            continue
        p = logs.ranges(ranges, key)
        m = table.c
        unit = m[key]
        query = (
            select(p.c.i, *(func.sum(m[flag]) for flag in STAT_FLAGS),
                   func.sum(m.starts), func.sum(m.starts * unit * per_minute),
                   func.sum(m.start_offset_ns), func.sum(m.ends),
                   func.sum(m.ends * unit * per_minute), func.sum(m.end_offset_ns),
                   func.sum(m.repairs), func.sum(m.repair_ns),
                   *(func.sum(m[name]) for name in GOAL_METRICS))
            .select_from(p.join(table, and_(unit >= p.c.a, unit < p.c.b)))
            .group_by(p.c.i)
        )
        for log_totals, rows in zip(totals, logs.rows(query), strict=True):
            for row in rows:
                i, *values = (int(v or 0) for v in row)
                found = log_totals.get(i)
                if found is None:
                    log_totals[i] = values
                else:
                    log_totals[i] = [a + b for a, b in zip(found, values, strict=True)]
    return [[(i, *log_totals[i]) for i in sorted(log_totals)] for log_totals in totals]


def busy_windows(logs: Logs, minute_edges: Sequence[tuple[int, int]], minutes: int,
                 above: int) -> list[list[tuple[int, int, int]]]:
    """Per log: (period i, window, confirmations) of grid windows of ``minutes`` with more
    than ``above`` confirmations inside period i."""
    p = logs.periods(minute_edges, "minute")
    m = stat_minutes.c
    window = (m.minute // minutes).label("w")
    total = func.sum(m.confirmation)
    query = (
        select(p.c.i, window, total)
        .select_from(p.join(stat_minutes, and_(m.minute >= p.c.a, m.minute < p.c.b)))
        .where(m.confirmation > 0)
        .group_by(p.c.i, window)
        .having(total > above)
    )
    return [[(int(i), int(w), int(n)) for i, w, n in rows] for rows in logs.rows(query)]


def top_confirmations(logs: Logs, edges: Sequence[tuple[int, int]],
                      top: int) -> list[dict[int, int]]:
    """Per log, per period i (bounds in ns): confirmations of its ``top`` most confirmed
    codes."""
    p = logs.periods(edges, "ns")
    f = stat_facts.c
    per_code = (
        select(p.c.i.label("i"), func.count().label("n"))
        .select_from(p.join(stat_facts, and_(f.confirmation == 1, f.at_ns >= p.c.a,
                                             f.at_ns < p.c.b)))
        .group_by(p.c.i, f.fault_code)
        .subquery()
    )
    ranked = select(
        per_code.c.i, per_code.c.n,
        func.row_number().over(partition_by=per_code.c.i, order_by=per_code.c.n.desc())
        .label("rank"),
    ).subquery()
    query = (select(ranked.c.i, func.sum(ranked.c.n)).where(ranked.c.rank <= top)
             .group_by(ranked.c.i))
    return [{int(i): int(n) for i, n in rows} for rows in logs.rows(query)]


def chattering(logs: Logs, edges: Sequence[tuple[int, int]]) -> list[dict[int, int]]:
    """Per log, per period i (bounds in ns): distinct codes with a chattering activation."""
    p = logs.periods(edges, "ns")
    f = stat_facts.c
    query = (
        select(p.c.i, func.count(f.fault_code.distinct()))
        .select_from(p.join(stat_facts, and_(f.chatter == 1, f.at_ns >= p.c.a,
                                             f.at_ns < p.c.b)))
        .group_by(p.c.i)
    )
    return [{int(i): int(n) for i, n in rows} for rows in logs.rows(query)]


def estops(logs: Logs, edges: Sequence[tuple[int, int]],
           only: Sequence[str]) -> list[dict[int, int]]:
    """Per log, per period i (bounds in ns): activations of the codes ``only`` (the
    e-stops), counted through the partial index of activations."""
    found: list[dict[int, int]] = [{} for _ in range(len(logs))]
    p = logs.periods(edges, "ns")
    f = stat_facts.c
    for chunk in _chunks(only):
        if not chunk:
            continue
        query = (
            select(p.c.i, func.count())
            .select_from(p.join(stat_facts, and_(
                f.activation == 1, f.fault_code.in_(chunk), f.at_ns >= p.c.a,
                f.at_ns < p.c.b)))
            .group_by(p.c.i)
        )
        for counts, rows in zip(found, logs.rows(query), strict=True):
            for i, n in rows:
                counts[int(i)] = counts.get(int(i), 0) + int(n)
    return found


def closed_open_at(logs: Logs, at_ns: int) -> list[int]:
    """Per log: ended episodes that were CONFIRMED at ``at_ns`` (start < at <= end)."""
    query = select(func.count()).select_from(stat_episodes).where(
        stat_episodes.c.start_ns < at_ns, stat_episodes.c.end_ns >= at_ns)
    return [int(rows[0][0]) if rows else 0 for rows in logs.rows(query)]


Span = tuple[str, int, int | None]
"""(code, start_ns, end_ns or None while open): what staleness and open time need."""


def open_spans(logs: Logs) -> list[list[Span]]:
    query = select(stat_episodes.c.fault_code, stat_episodes.c.start_ns,
                   stat_episodes.c.end_ns).where(stat_episodes.c.end_ns.is_(None))
    return [[(code, int(start), None) for code, start, _ in rows] for rows in logs.rows(query)]


def long_spans(logs: Logs, since_ns: int, until_ns: int, min_ns: int) -> list[list[Span]]:
    """Per log: ended episodes of at least ``min_ns`` that end after ``since_ns`` and start
    before ``until_ns - min_ns`` (the stale candidates; the partial index holds only long
    ones)."""
    e = stat_episodes.c
    # The length as a literal, so SQLite sees that the partial index's condition holds.
    query = select(e.fault_code, e.start_ns, e.end_ns).where(
        e.end_ns - e.start_ns >= literal_column(str(int(min_ns))), e.end_ns > since_ns,
        e.start_ns < until_ns - min_ns)
    return [[(code, int(start), int(end)) for code, start, end in rows]
            for rows in logs.rows(query)]


def codes(conn: Connection) -> list[str]:
    """Every code the statistics know (globs are matched against these)."""
    return codes_of(Logs(conn))[0]


def codes_of(logs: Logs) -> list[list[str]]:
    """Per log: every code its statistics know."""
    return [[row[0] for row in rows] for rows in logs.rows(select(stat_codes.c.fault_code))]


def facts_of(logs: Logs, since_ns: int, until_ns: int) -> list[list[StatFact]]:
    """Per log: its facts in [since, until) (a partial minute's)."""
    return [[StatFact(*row) for row in rows] for rows in logs.rows(_facts(since_ns, until_ns))]


def goals_of(logs: Logs, since_ns: int, until_ns: int) -> list[list[GoalFact]]:
    """Per log: its goal outcomes in [since, until) (a partial minute's)."""
    return [[GoalFact(*row) for row in rows] for rows in logs.rows(_goals(since_ns, until_ns))]


def facts(conn: Connection, since_ns: int, until_ns: int,
          only: Sequence[str] | None) -> list[StatFact]:
    """Facts in [since, until), of the codes ``only`` (None: all)."""
    found: list[StatFact] = []
    for chunk in _chunks(only):
        query = _facts(since_ns, until_ns)
        if chunk is not None:
            query = query.where(stat_facts.c.fault_code.in_(chunk))
        found.extend(StatFact(*row) for row in fastpath.fetch_all_rendered(conn, query))
    return found


def _facts(since_ns: int, until_ns: int) -> Any:
    return select(stat_facts).where(stat_facts.c.at_ns >= since_ns,
                                    stat_facts.c.at_ns < until_ns)


def _goals(since_ns: int, until_ns: int) -> Any:
    return select(stat_goals).where(stat_goals.c.at_ns >= since_ns,
                                    stat_goals.c.at_ns < until_ns)


def operator_facts(logs: Logs, since_ns: int, until_ns: int) -> list[list[OperatorFact]]:
    """Per log: acknowledgements in [since, until) and shelvings that began before
    ``until`` and had not ended by ``since`` (few rows: people's actions)."""
    table = stat_operator
    query = select(*(table.c[name] for name in _OPERATOR_COLUMNS)).where(
        table.c.at_ns < until_ns,
        or_(table.c.at_ns >= since_ns,
            and_(table.c.kind == SHELF, or_(table.c.end_ns.is_(None),
                                            table.c.end_ns > since_ns))))
    return [[OperatorFact(*row) for row in rows] for rows in logs.rows(query)]


def goals(conn: Connection, since_ns: int, until_ns: int) -> list[GoalFact]:
    """Goal outcomes in [since, until) (through ix_stat_goals_at)."""
    return [GoalFact(*row) for row in fastpath.fetch_all_rendered(conn,
                                                                  _goals(since_ns, until_ns))]


def edge_episodes(logs: Logs, since_ns: int, until_ns: int) -> list[list[Episode]]:
    """Per log: episodes that start, or whose ending record lies, in [since, until): the
    episode edges of a part of a minute (the minute table holds whole minutes)."""
    e = stat_episodes.c
    query = select(stat_episodes).where(or_(
        and_(e.start_ns >= since_ns, e.start_ns < until_ns),
        and_(e.end_ns >= since_ns, e.end_ns < until_ns)))
    return [[Episode(*row) for row in rows] for rows in logs.rows(query)]


def episodes(conn: Connection, since_ns: int, until_ns: int,
             only: Sequence[str] | None) -> list[Episode]:
    """Episodes that overlap [since, until) or are still open (the caller ends those)."""
    e = stat_episodes.c
    overlaps = or_(
        and_(e.start_ns < until_ns, or_(e.end_ns.is_(None), e.end_ns > since_ns)),
        and_(e.end_ns >= since_ns, e.end_ns < until_ns),  # a repair even if the clock ran back
    )
    found: list[Episode] = []
    for chunk in _chunks(only):
        query = select(stat_episodes).where(overlaps)
        if chunk is not None:
            query = query.where(stat_episodes.c.fault_code.in_(chunk))
        found.extend(Episode(*row) for row in fastpath.fetch_all_rendered(conn, query))
    return found


def count_records(conn: Connection, since_ns: int, until_ns: int,
                  only: Sequence[str] | None, *, faults: bool, goals: bool, most: int) -> int:
    """How many rows ``facts``, ``episodes`` (with ``faults``) and ``goals`` (with ``goals``)
    would read for [since, until) and the codes ``only``, counted in their indexes without
    reading a row; counting stops past ``most`` (a huge range costs no more to refuse than
    one just over the limit)."""
    e = stat_episodes.c
    overlaps = or_(
        and_(e.start_ns < until_ns, or_(e.end_ns.is_(None), e.end_ns > since_ns)),
        and_(e.end_ns >= since_ns, e.end_ns < until_ns),
    )
    window = and_(stat_facts.c.at_ns >= since_ns, stat_facts.c.at_ns < until_ns)
    found = 0

    def capped(query: Any) -> int:
        limited = query.limit(most + 1 - found).subquery()
        return int(conn.execute(select(func.count()).select_from(limited)).scalar_one())

    if goals:
        found += capped(select(literal_column("1")).select_from(stat_goals).where(
            stat_goals.c.at_ns >= since_ns, stat_goals.c.at_ns < until_ns))
    if faults:
        for chunk in _chunks(only):
            for table, where in ((stat_facts, window), (stat_episodes, overlaps)):
                if found > most:
                    return found
                query: Any = select(literal_column("1")).select_from(table).where(where)
                if chunk is not None:
                    query = query.where(table.c.fault_code.in_(chunk))
                found += capped(query)
    return found


def _chunks(only: Sequence[str] | None) -> Iterable[Sequence[str] | None]:
    if only is None:
        yield None
        return
    for start in range(0, len(only), _CODE_CHUNK):
        yield only[start:start + _CODE_CHUNK]


def differences(conn: Connection, replayed: StatsOutput) -> list[str]:
    """Which statistics tables differ from a full replay's output (for ``verify``)."""
    problems: list[str] = []
    stored_facts = [StatFact(*row) for row in conn.execute(
        select(stat_facts).order_by(stat_facts.c.seq))]
    if stored_facts != replayed.facts:
        problems.append("stat_facts")
    episodes = {e.start_seq: e for e in replayed.started}
    episodes.update((e.start_seq, e) for e in replayed.ended)
    stored_episodes = {row.start_seq: _episode(row) for row in conn.execute(select(stat_episodes))}
    if stored_episodes != episodes:
        problems.append("stat_episodes")
    minutes, hours = _minute_and_hour_rows(replayed)
    expected_minutes = {row["minute"]: row for row in minutes}
    stored_minutes = {row["minute"]: dict(row) for row in conn.execute(
        select(stat_minutes)).mappings()}
    if stored_minutes != expected_minutes:
        problems.append("stat_minutes")
    expected_hours = {row["hour"]: row for row in hours}
    stored_hours = {row["hour"]: dict(row) for row in conn.execute(
        select(stat_hours)).mappings()}
    if stored_hours != expected_hours:
        problems.append("stat_hours")
    if load_tracks(conn) != replayed.tracks:
        problems.append("stat_codes")
    stored_goals = [GoalFact(*row) for row in conn.execute(
        select(stat_goals).order_by(stat_goals.c.seq))]
    if stored_goals != replayed.goals:
        problems.append("stat_goals")
    return [f"{name} differs from a full replay of the log" for name in problems]
