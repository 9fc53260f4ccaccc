"""Batch sizes that follow the central's pace (fleet/pace.py)."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from faultledger.fleet.pace import BatchPace


def test_a_robot_alone_on_a_fast_central_sends_full_batches_from_its_third() -> None:
    pace = BatchPace(1_000)
    sizes = [pace.size]
    for _ in range(4):
        pace.answered(pace.size, pace.size / 40_000)  # the central takes 40,000 records/s
        sizes.append(pace.size)
    assert sizes == [250, 500, 1_000, 1_000, 1_000]


def test_a_busy_central_makes_batches_that_are_answered_in_about_a_tenth_of_a_second() -> None:
    pace = BatchPace(1_000)
    for _ in range(10):  # the central gives this robot 2,000 records/s
        pace.answered(pace.size, pace.size / 2_000)
    assert pace.size == 300  # answered in 0.15 s


def test_the_size_at_most_halves_or_doubles_per_answer_and_recovers() -> None:
    pace = BatchPace(1_000)
    pace.answered(250, 0.001)
    pace.answered(500, 0.001)
    assert pace.size == 1_000
    pace.answered(1_000, 10.0)  # one very slow answer
    assert pace.size == 500
    sizes = []
    for _ in range(4):
        pace.answered(pace.size, 0.001)
        sizes.append(pace.size)
    assert sizes == [1_000, 1_000, 1_000, 1_000]
    pace.answered(1_000, 10.0)
    pace.answered(500, 10.0)
    pace.answered(250, 10.0)
    pace.answered(125, 10.0)
    assert pace.size == 62
    pace.answered(62, 10.0)
    assert pace.size == 50  # never fewer
    pace.answered(50, 0.001)
    assert pace.size == 100


@given(st.lists(st.tuples(st.integers(0, 1_000), st.floats(0, 30)), max_size=50),
       st.integers(1, 1_000))
def test_the_size_stays_within_its_bounds(answers: list[tuple[int, float]], most: int) -> None:
    pace = BatchPace(most)
    for records, seconds in answers:
        before = pace.size
        pace.answered(records, seconds)
        assert min(50, most) <= pace.size <= most
        if records:
            assert before // 2 <= pace.size <= before * 2
