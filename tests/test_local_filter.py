"""The FaultReporter's local filter (SPEC §8, ros2_medkit semantics), on a fake clock, no ROS."""

from __future__ import annotations

import math

import pytest

from faultledger.ros.local_filter import FilterConfig, LocalFilter

INFO, WARN, ERROR, CRITICAL = 0, 1, 2, 3
PASSED = None  # a step's severity None means report_passed
Step = tuple[float, str, int | None, bool]  # (time s, fault code, severity or PASSED, forwarded)

CASES: dict[str, tuple[FilterConfig, list[Step]]] = {
    "third report within the window is forwarded, and every later one": (FilterConfig(), [
        (0.0, "A", WARN, False), (1.0, "A", WARN, False), (2.0, "A", WARN, True),
        (3.0, "A", INFO, True), (4.0, "A", WARN, True)]),
    "reports older than the window no longer count": (FilterConfig(), [
        (0.0, "A", WARN, False), (1.0, "A", WARN, False), (11.5, "A", WARN, False),
        (12.0, "A", WARN, False), (12.5, "A", WARN, True)]),
    "a report exactly window seconds old still counts": (FilterConfig(), [
        (0.0, "A", WARN, False), (5.0, "A", WARN, False), (10.0, "A", WARN, True)]),
    "the count is sliding, not reset by forwarding": (FilterConfig(), [
        (0.0, "A", WARN, False), (4.0, "A", WARN, False), (8.0, "A", WARN, True),
        (12.0, "A", WARN, True), (30.0, "A", WARN, False)]),
    "ERROR and CRITICAL bypass at once and are not counted": (FilterConfig(), [
        (0.0, "A", ERROR, True), (0.1, "A", CRITICAL, True), (0.2, "A", WARN, False),
        (0.3, "A", WARN, False), (0.4, "A", WARN, True)]),
    "bypass_severity 1 lets WARN through but counts INFO": (FilterConfig(bypass_severity=1), [
        (0.0, "A", WARN, True), (0.1, "A", INFO, False)]),
    "bypass_severity 4 makes CRITICAL wait for the threshold too":
        (FilterConfig(bypass_severity=4), [
            (0.0, "A", CRITICAL, False), (0.1, "A", CRITICAL, False), (0.2, "A", CRITICAL, True)]),
    "PASSED is counted apart from FAILED": (FilterConfig(), [
        (0.0, "A", WARN, False), (0.1, "A", PASSED, False), (0.2, "A", WARN, False),
        (0.3, "A", PASSED, False), (0.4, "A", WARN, True), (0.5, "A", PASSED, True)]),
    "PASSED is filtered even after a bypassing ERROR": (FilterConfig(), [
        (0.0, "A", ERROR, True), (0.1, "A", PASSED, False), (0.2, "A", PASSED, False),
        (0.3, "A", PASSED, True)]),
    "fault codes are counted independently": (FilterConfig(), [
        (0.0, "A", WARN, False), (0.1, "B", WARN, False), (0.2, "A", WARN, False),
        (0.3, "B", WARN, False), (0.4, "A", WARN, True), (0.5, "C", WARN, False),
        (0.6, "B", WARN, True)]),
    "a disabled filter forwards everything": (FilterConfig(enabled=False), [
        (0.0, "A", INFO, True), (0.0, "A", PASSED, True), (0.1, "B", WARN, True)]),
    "threshold 1 forwards the first report": (FilterConfig(default_threshold=1), [
        (0.0, "A", INFO, True), (0.1, "A", PASSED, True)]),
    "a short window forgets quickly": (FilterConfig(default_window_sec=0.5), [
        (0.0, "A", WARN, False), (0.4, "A", WARN, False), (0.8, "A", WARN, False),
        (0.85, "A", WARN, True)]),
}


@pytest.mark.parametrize("name", list(CASES))
def test_filter_decisions(name: str) -> None:
    config, steps = CASES[name]
    now = [0.0]
    local = LocalFilter(config, clock=lambda: now[0])
    for at, code, severity, forwarded in steps:
        now[0] = at
        got = (local.should_forward_passed(code) if severity is None
               else local.should_forward(code, severity))
        assert got is forwarded, f"{name}: at t={at} {code} severity={severity}"


def test_defaults_match_medkit() -> None:
    assert FilterConfig() == FilterConfig(enabled=True, default_threshold=3,
                                          default_window_sec=10.0, bypass_severity=2)


def test_reset_forgets_counts() -> None:
    local = LocalFilter(FilterConfig(), clock=lambda: 0.0)
    assert not local.should_forward("A", WARN)
    assert not local.should_forward("A", WARN)
    local.reset()
    assert not local.should_forward("A", WARN)


def test_memory_per_code_is_bounded_by_the_threshold() -> None:
    local = LocalFilter(FilterConfig(), clock=lambda: 0.0)
    for _ in range(10_000):
        local.should_forward("A", WARN)
    assert len(local._failed["A"]) == 3


NORMALISED: list[tuple[str, object, object, str]] = [
    # (parameter, raw value, normalised value, text the warning must contain)
    ("default_threshold", 0, 1, "default_threshold=0"),
    ("default_threshold", -5, 1, "default_threshold=-5"),
    ("default_threshold", "three", 3, "default_threshold='three'"),
    ("default_threshold", 2.5, 3, "default_threshold=2.5"),
    ("default_threshold", True, 3, "default_threshold=True"),
    ("default_window_sec", 0.0, 1.0, "default_window_sec=0.0"),
    ("default_window_sec", -3.0, 1.0, "default_window_sec=-3.0"),
    ("default_window_sec", math.nan, 1.0, "default_window_sec=nan"),
    ("default_window_sec", math.inf, 1.0, "default_window_sec=inf"),
    ("default_window_sec", None, 10.0, "default_window_sec=None"),
    ("bypass_severity", -1, 0, "bypass_severity=-1"),
    ("bypass_severity", 255, 4, "bypass_severity=255"),
    ("bypass_severity", "ERROR", 2, "bypass_severity='ERROR'"),
    ("enabled", "yes", True, "enabled='yes'"),
    ("enabled", 0, True, "enabled=0"),
]


@pytest.mark.parametrize(("name", "raw", "expected", "warning"), NORMALISED)
def test_out_of_range_parameters_are_normalised_with_a_warning(
        name: str, raw: object, expected: object, warning: str) -> None:
    values: dict[str, object] = {"enabled": True, "default_threshold": 3,
                                 "default_window_sec": 10.0, "bypass_severity": 2}
    values[name] = raw
    config, problems = FilterConfig.from_raw(**values)
    assert getattr(config, name) == expected
    assert len(problems) == 1
    assert f"fault_reporter.local_filtering.{warning}" in problems[0]


ACCEPTED: list[tuple[str, object, object]] = [
    ("default_threshold", 1, 1), ("default_threshold", 3.0, 3),
    ("default_window_sec", 10, 10.0), ("default_window_sec", 0.25, 0.25),
    ("bypass_severity", 0, 0), ("bypass_severity", 4, 4), ("enabled", False, False),
]


@pytest.mark.parametrize(("name", "raw", "expected"), ACCEPTED)
def test_valid_parameters_pass_without_warning(name: str, raw: object, expected: object) -> None:
    values: dict[str, object] = {"enabled": True, "default_threshold": 3,
                                 "default_window_sec": 10.0, "bypass_severity": 2}
    values[name] = raw
    config, problems = FilterConfig.from_raw(**values)
    assert problems == []
    assert getattr(config, name) == expected
    assert type(getattr(config, name)) is type(expected)


def test_a_hand_built_bad_config_is_an_error() -> None:
    with pytest.raises(ValueError, match="default_threshold=0"):
        FilterConfig(default_threshold=0)
