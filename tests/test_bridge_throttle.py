"""The bridges' one warning throttle (``faultledger.ros.bridges.throttle``), on a fake clock."""

from __future__ import annotations

from faultledger.ros.bridges.throttle import Throttle


class FakeClock:
    """A monotonic clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def throttle(interval: float = 10.0, **kwargs: int) -> tuple[Throttle, FakeClock, list[str]]:
    clock, out = FakeClock(), list[str]()
    return Throttle(out.append, interval, clock, **kwargs), clock, out


def test_one_message_per_key_per_interval_with_a_count_of_those_held_back() -> None:
    t, clock, out = throttle()
    assert t.warn("a", "first a")
    assert not t.warn("a", "second a")
    assert t.warn("b", "first b")
    clock.now = 5.0
    assert not t.warn("a", "third a")
    assert t.suppressed("a") == 2 and t.suppressed("b") == 0
    clock.now = 10.0  # exactly one interval later: speaks again
    assert t.warn("a", "fourth a")
    assert t.suppressed("a") == 0
    clock.now = 25.0
    assert t.warn("a", "fifth a")  # nothing held back since the last one: no count
    assert out == ["first a", "first b", "fourth a (2 similar suppressed)", "fifth a"]


def test_keys_are_independent() -> None:
    t, clock, out = throttle()
    for key in ("a", "b", "a", "b", "c"):
        t.warn(key, key)
    clock.now = 11.0
    t.warn("b", "b again")
    t.warn("c", "c again")
    assert out == ["a", "b", "c", "b again (1 similar suppressed)", "c again"]


def test_the_interval_counts_from_the_last_message_let_through() -> None:
    t, clock, out = throttle(interval=1.0)
    for now in (0.0, 0.4, 0.9, 1.0, 1.5, 1.99, 2.0):
        clock.now = now
        t.warn("k", f"at {now}")
    assert out == ["at 0.0", "at 1.0 (2 similar suppressed)", "at 2.0 (2 similar suppressed)"]


def test_a_zero_interval_lets_everything_through() -> None:
    t, _, out = throttle(interval=0.0)
    assert all(t.warn("k", str(i)) for i in range(3))
    assert out == ["0", "1", "2"]


def test_keys_remembered_are_bounded() -> None:
    t, _, out = throttle(max_keys=2)
    t.warn("a", "a")
    t.warn("a", "a held")  # counted for "a"
    t.warn("b", "b")
    t.warn("c", "c")  # "a" spoke longest ago: forgotten with its count
    assert t.suppressed("a") == 0
    assert t.warn("a", "a at once")  # a forgotten key speaks at once
    assert not t.warn("c", "c held")  # the newest keys are still throttled
    assert out == ["a", "b", "c", "a at once"]


def test_the_default_clock_is_monotonic() -> None:
    out: list[str] = []
    t = Throttle(out.append, 3600.0)
    assert t.warn("k", "1") and not t.warn("k", "2")
    assert out == ["1"]
