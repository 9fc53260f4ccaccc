"""Robot logs a central has stored records of but not yet projected (docs/fleet.md,
"Storing first, projecting behind").

A push is acknowledged once its records are committed under the log's write lock; bringing
the log's projections and statistics up to them is left to this backlog: it projects a log
when pushes have paused for ``quiet`` seconds, at once when a log lags by ``max_lag`` records,
and before any read that needs them (``current``). So a burst of pushes goes at the speed of
storing records, a supervisor's read still sees every acknowledged record, and a read after a
long burst waits for at most ``max_lag`` records per log. Should the central stop before
projecting, whoever next opens the log finds its projections behind its records and brings
them up (service/restore.py); ``scan`` finds such logs when the backlog starts.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable

log = logging.getLogger(__name__)

QUIET_SECONDS = 0.3
"""Pause in pushes after which the backlog projects the logs behind."""
MAX_LAG = 20_000
"""Records a log may be behind before it is projected even while pushes go on (about half a
second of projection on this project's reference machine, docs/performance.md)."""
RETRY_SECONDS = 5.0


class Backlog:
    """Logs (by chain id) behind their records, and the thread that projects them."""

    def __init__(self, project: Callable[[int], None], scan: Callable[[], Iterable[int]],
                 quiet: float = QUIET_SECONDS, max_lag: int = MAX_LAG) -> None:
        self._project = project
        self._scan = scan
        self._quiet = quiet
        self._max_lag = max_lag
        self._changed = threading.Condition()
        self._behind: dict[int, int] = {}
        self._last_store = 0.0
        self._retry_at = 0.0
        self._scanned = threading.Event()
        self._locks: dict[int, threading.Lock] = {}
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="faultledger-fleet-projector",
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        with self._changed:
            self._stop = True
            self._changed.notify_all()
        self._thread.join(timeout=30)

    def stored(self, chain_id: int, records: int) -> None:
        """A push committed ``records`` new records to a log."""
        if records <= 0:
            return
        with self._changed:
            self._behind[chain_id] = self._behind.get(chain_id, 0) + records
            self._last_store = time.monotonic()
            self._changed.notify_all()

    def behind(self) -> dict[int, int]:
        """Records per log stored but not yet projected (``/metrics``)."""
        with self._changed:
            return dict(self._behind)

    def current(self, chain_id: int) -> None:
        """Return once the log's projections include every record acknowledged so far."""
        self._scanned.wait()
        with self._lock(chain_id):
            with self._changed:
                lag = self._behind.pop(chain_id, 0)
            if not lag:
                return
            try:
                self._project(chain_id)
            except BaseException:
                with self._changed:
                    self._behind[chain_id] = self._behind.get(chain_id, 0) + lag
                raise

    def _lock(self, chain_id: int) -> threading.Lock:
        with self._changed:
            return self._locks.setdefault(chain_id, threading.Lock())

    def _run(self) -> None:
        try:
            found = list(self._scan())
        except Exception as error:  # the database away at start: reads project as they go
            log.warning("cannot look for robot logs behind their records: %s", error)
            found = []
        with self._changed:
            for chain_id in found:
                self._behind.setdefault(chain_id, 1)
        self._scanned.set()
        while True:
            due = self._next()
            if due is None:
                return
            try:
                self.current(due)
            except Exception as error:
                log.warning("projecting robot log %d failed (%s); retrying in %.0f s",
                            due, error, RETRY_SECONDS)
                with self._changed:
                    self._retry_at = time.monotonic() + RETRY_SECONDS

    def _next(self) -> int | None:
        """The next log to project, once it is time to (None: closing)."""
        with self._changed:
            while not self._stop:
                now = time.monotonic()
                wait = max(self._last_store + self._quiet, self._retry_at) - now
                if self._behind:
                    chain_id, lag = max(self._behind.items(), key=lambda item: item[1])
                    if wait <= 0 or (lag >= self._max_lag and self._retry_at <= now):
                        return chain_id
                    self._changed.wait(max(wait, 0.01))
                else:
                    self._changed.wait()
            return None
