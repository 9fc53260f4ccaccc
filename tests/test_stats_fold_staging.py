"""The statistics fold is staged with the projector: a group commit that fails leaves its
output and code tracks exactly as before the group (service/writer.py rolls back), also when
the output was handed over (``take``) in the middle of the group."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from faultledger.domain.events import FaultCleared, FaultReported, LogRecord
from faultledger.domain.projector import Projector
from faultledger.domain.statistics import StatsFold, StatsOutput
from faultledger.domain.types import EventType

SECOND = 1_000_000_000
REPORTS = st.lists(st.tuples(st.integers(0, 3), st.booleans(), st.integers(0, 3)),
                   max_size=30)
"""(code, failed, severity) per report."""


def records(reports: list[tuple[int, bool, int]], first_seq: int) -> list[LogRecord]:
    return [LogRecord(first_seq + i, f"id-{first_seq + i}", FaultReported(
        f"CODE_{code}", EventType.FAILED if failed else EventType.PASSED, severity, "",
        "/src"), (first_seq + i) * SECOND, (first_seq + i) * SECOND)
        for i, (code, failed, severity) in enumerate(reports)]


def folded(reports: list[tuple[int, bool, int]]) -> Projector:
    projector = Projector(stats=StatsFold())
    projector.apply_all(records(reports, 1))
    return projector


def state(projector: Projector) -> tuple[StatsOutput, dict[str, object]]:
    assert projector.stats is not None
    out = projector.stats.peek()
    return (StatsOutput(list(out.facts), list(out.started), list(out.ended), dict(out.tracks),
                        list(out.goals), list(out.operator), list(out.shelf_ends)),
            dict(projector.stats.tracks()))


@given(before=REPORTS, group=REPORTS)
def test_a_rolled_back_group_leaves_the_fold_as_before(
        before: list[tuple[int, bool, int]], group: list[tuple[int, bool, int]]) -> None:
    projector = folded(before)
    expected = state(projector)
    projector.stage()
    for record in records(group, len(before) + 1):
        projector.apply(record)
    projector.rollback()
    assert state(projector) == expected
    assert state(projector) == state(folded(before))  # the same as never having seen it


@given(before=REPORTS, taken=REPORTS, after=REPORTS)
def test_a_rollback_after_a_take_in_the_group_drops_only_what_followed(
        before: list[tuple[int, bool, int]], taken: list[tuple[int, bool, int]],
        after: list[tuple[int, bool, int]]) -> None:
    """A save inside the group takes the output; should the group then fail, the fold's output
    holds nothing of the group and the code tracks are those before it."""
    projector = folded(before)
    tracks_before = state(projector)[1]
    assert projector.stats is not None
    projector.stage()
    for record in records(taken, len(before) + 1):
        projector.apply(record)
    projector.stats.take()
    for record in records(after, len(before) + len(taken) + 1):
        projector.apply(record)
    projector.rollback()
    output, tracks = state(projector)
    assert output == StatsOutput([], [], [], {}, [], [], [])
    assert tracks == tracks_before


def test_a_rolled_back_clear_leaves_the_episode_it_ended_open() -> None:
    """An episode confirmed in an earlier (unsaved) group and ended by a clear in the failed
    group: the clear rewrites the episode in the fold's output in place, and the rollback
    must put back the open one (else the next save writes an episode ended by a record the
    log never kept)."""
    projector = folded([(0, True, 2)])
    assert projector.stats is not None
    assert [e.end_seq for e in projector.stats.peek().started] == [None]
    expected = state(projector)
    projector.stage()
    projector.apply(LogRecord(2, "id-2", FaultCleared("CODE_0", "operator", "fixed"),
                              2 * SECOND, 2 * SECOND))
    assert [e.end_seq for e in projector.stats.peek().started] == [2]  # ended in place
    projector.rollback()
    assert [e.end_seq for e in projector.stats.peek().started] == [None]
    assert state(projector) == expected
