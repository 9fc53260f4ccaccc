"""The reporter's local filter: a flapping check must not flood the fault manager (SPEC §8).

Pure logic (no rclpy, clock injected) with ros2_medkit's semantics: per fault code, a report is
forwarded once ``default_threshold`` reports of that code fall within the last
``default_window_sec`` seconds (and so is every further report while that holds); FAILED reports
with severity >= ``bypass_severity`` are forwarded at once and not counted; PASSED reports are
counted apart from FAILED ones; a disabled filter forwards everything.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

PARAMETER_PREFIX = "fault_reporter.local_filtering."
NO_BYPASS = 4
"""bypass_severity above SEVERITY_CRITICAL (3): no severity skips the count."""


@dataclass(frozen=True)
class FilterConfig:
    """Filter settings; the defaults are medkit's (3 reports within 10 s, ERROR bypasses)."""

    enabled: bool = True
    default_threshold: int = 3
    default_window_sec: float = 10.0
    bypass_severity: int = 2

    def __post_init__(self) -> None:
        # Code that builds a config by hand gets an error; ROS parameters go through from_raw.
        values, problems = _normalise(
            self.enabled, self.default_threshold, self.default_window_sec, self.bypass_severity)
        if problems:
            raise ValueError("; ".join(problems))
        object.__setattr__(self, "default_window_sec", values[2])  # an int window becomes float

    @classmethod
    def from_raw(cls, enabled: object, default_threshold: object, default_window_sec: object,
                 bypass_severity: object) -> tuple[FilterConfig, list[str]]:
        """Config from untrusted values (ROS parameters of any type): normalised, never raising.

        Returns the config and one message per value it had to change, naming that value. As in
        medkit, a threshold below 1 becomes 1 and a non-positive window 1.0 s; bypass_severity is
        clamped to 0..4 (4 = nothing bypasses); a value of the wrong type takes the default.
        """
        values, problems = _normalise(enabled, default_threshold, default_window_sec,
                                      bypass_severity)
        return cls(*values), problems


def _normalise(enabled: object, threshold: object, window: object,
               bypass: object) -> tuple[tuple[bool, int, float, int], list[str]]:
    problems: list[str] = []

    def note(name: str, value: object, why: str, used: object) -> None:
        problems.append(f"{PARAMETER_PREFIX}{name}={value!r} {why}; using {used!r}")

    on = enabled if isinstance(enabled, bool) else FilterConfig.enabled
    if on is not enabled:
        note("enabled", enabled, "is not a bool", on)
    count = _as_int("default_threshold", threshold, FilterConfig.default_threshold, 1, None, note)
    level = _as_int("bypass_severity", bypass, FilterConfig.bypass_severity, 0, NO_BYPASS, note)
    if isinstance(window, bool) or not isinstance(window, int | float):
        seconds = FilterConfig.default_window_sec
        note("default_window_sec", window, "is not a number", seconds)
    elif not (math.isfinite(window) and window > 0):
        seconds = 1.0
        note("default_window_sec", window, "is not a positive finite number", seconds)
    else:
        seconds = float(window)
    return (on, count, seconds, level), problems


def _as_int(name: str, value: object, default: int, low: int, high: int | None,
            note: Callable[[str, object, str, object], None]) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)  # 3.0 from a YAML file means 3
    if isinstance(value, bool) or not isinstance(value, int):
        note(name, value, "is not an integer", default)
        return default
    clamped = max(value, low) if high is None else min(max(value, low), high)
    if clamped != value:
        note(name, value, f"is below {low}" if high is None else f"is outside {low}..{high}",
             clamped)
    return clamped


class LocalFilter:
    """Decides per report whether it goes to the manager. Not thread-safe: callers lock."""

    def __init__(self, config: FilterConfig | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config or FilterConfig()
        self._clock = clock
        self._failed: dict[str, deque[float]] = {}
        self._passed: dict[str, deque[float]] = {}

    def should_forward(self, fault_code: str, severity: int) -> bool:
        """Count one FAILED report; True if it is to be sent."""
        if not self.config.enabled or severity >= self.config.bypass_severity:
            return True
        return self._count(self._failed, fault_code)

    def should_forward_passed(self, fault_code: str) -> bool:
        """Count one PASSED report (its own tally, so healing is debounced too)."""
        if not self.config.enabled:
            return True
        return self._count(self._passed, fault_code)

    def reset(self) -> None:
        """Forget every count (e.g. after the configuration changed)."""
        self._failed.clear()
        self._passed.clear()

    def _count(self, tallies: dict[str, deque[float]], fault_code: str) -> bool:
        # Only the newest `threshold` times matter: the report passes when the oldest of them is
        # still inside the window. So a deque of that length bounds memory under a storm.
        now = self._clock()
        times = tallies.get(fault_code)
        if times is None:
            times = tallies[fault_code] = deque(maxlen=self.config.default_threshold)
        cutoff = now - self.config.default_window_sec
        while times and times[0] < cutoff:
            times.popleft()
        times.append(now)
        return len(times) >= self.config.default_threshold
