"""The bridges' warning throttle (no rclpy): bad input must be seen, not flood the log."""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Callable

MAX_KEYS = 1024
"""Keys remembered; beyond this the one that spoke longest ago is forgotten (its next warning
is then shown at once), so keys made of input (hardware ids, topics) cannot grow memory."""


class Throttle:
    """At most one message per key per ``interval`` seconds of ``clock`` (monotonic).

    A message held back is counted; the next one of that key that is let through ends in
    ``(N similar suppressed)``.
    """

    def __init__(self, emit: Callable[[str], None], interval: float,
                 clock: Callable[[], float] = time.monotonic, max_keys: int = MAX_KEYS) -> None:
        self._emit = emit
        self._interval = interval
        self._clock = clock
        self._max_keys = max(max_keys, 1)
        self._last: OrderedDict[str, float] = OrderedDict()
        self._held: dict[str, int] = {}

    def warn(self, key: str, text: str) -> bool:
        """Emit ``text`` unless ``key`` spoke less than ``interval`` ago; True when emitted."""
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self._interval:
            self._held[key] = self._held.get(key, 0) + 1
            return False
        held = self._held.pop(key, 0)
        self._last[key] = now
        self._last.move_to_end(key)
        while len(self._last) > self._max_keys:
            old, _ = self._last.popitem(last=False)
            self._held.pop(old, None)
        self._emit(f"{text} ({held} similar suppressed)" if held else text)
        return True

    def suppressed(self, key: str) -> int:
        """Messages of ``key`` held back since it last spoke."""
        return self._held.get(key, 0)
