"""The live notification stream behind ``GET /api/v1/faults/stream`` (docs/http.md, "Stream").

One hub per server subscribes to the ledger once. The writer's callback only appends the
notification to a shared, bounded buffer and wakes the event loop, so no number of stream
clients, fast or stalled, ever slows a report. Each client reads the buffer with its own cursor
and encodes nothing itself: every notification is encoded once, on first use, and the bytes of
one wake-up are joined once for all the clients standing at the same cursor.

A client whose cursor falls off the buffer (it stalled for more than ``capacity``
notifications) is disconnected; it reconnects with ``Last-Event-ID`` and catches up from the
log, like a client that was away or a server that restarted. Event ids are log seqs, so the
catch-up sends every notification after that id exactly once.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field

from faultledger.domain.notifications import Notification
from faultledger.service.ledger import FaultLedger, Subscription

Encoder = Callable[[Notification], dict[str, object]]

DEFAULT_CAPACITY = 10_000
CATCH_UP_PAGE = 1_000
"""Notifications derived from the log per read while a client catches up."""
COALESCE_SEC = 0.025
"""The clients are woken this long after the first notification of a quiet spell, and each
then sends everything new in one write: under a burst, one send per client per 25 ms instead
of one per notification. One timer for the hub, not one per client: each client used to wake
twice per window (once to start its own 25 ms sleep, once at its end), two scheduling rounds of
the event loop per client that the reports' answers share (docs/performance.md, HTTP stream)."""
WAKE_GROUPS = 8
"""The clients are woken in this many groups, one group per turn of the event loop: a report's
answer that becomes ready meanwhile goes out between two groups, not after every client's
write (100 writes take the loop a few milliseconds)."""


@dataclass(slots=True)
class _Item:
    notification: Notification
    frame: bytes | None = None


@dataclass(slots=True)
class _Buffer:
    items: list[_Item] = field(default_factory=list)
    base: int = 0
    """Absolute index of items[0]: cursors stay valid while old items are dropped."""
    covered_after: int = 0
    """Every notification with a seq above this one is in the buffer (or was dropped from it,
    which moves this mark up)."""


class StreamHub:
    """Fans the ledger's notifications out to any number of SSE clients."""

    def __init__(self, ledger: FaultLedger, encode: Encoder,
                 capacity: int = DEFAULT_CAPACITY) -> None:
        self._ledger = ledger
        self._encode = encode
        self._capacity = capacity
        self._lock = threading.Lock()
        self._buffer = _Buffer()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._changed: list[asyncio.Event] = []
        """One event per wake group, replaced at each wake-up."""
        self._next_group = 0
        self._wake_pending = False
        self._subscription: Subscription | None = None
        self._stopped = False
        self.clients = 0
        self.dropped_clients = 0
        self._joined: tuple[int, int, bytes] | None = None
        """(cursor, end, bytes) of the last whole take (event loop only)."""

    # -- lifecycle (on the server's event loop) ---------------------------------------------
    def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._changed = [asyncio.Event() for _ in range(WAKE_GROUPS)]
        self._subscription = self._ledger.subscribe(self._on_notification)
        with self._lock:
            self._buffer.covered_after = self._ledger.last_seq

    def close(self) -> None:
        """End every stream now, from any thread (the server is stopping): each client's
        ``events`` returns, so its response ends with the closing chunk instead of being cut
        off mid-stream. New streams end at once."""
        loop = self._loop
        if loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop is already closed
                loop.call_soon_threadsafe(self.stop)

    def stop(self) -> None:
        self._stopped = True
        if self._subscription is not None:
            self._subscription.cancel()
            self._subscription = None
        for changed in self._changed:
            changed.set()

    # -- writer side (any thread) -----------------------------------------------------------
    def _on_notification(self, notification: Notification) -> None:
        buffer = self._buffer
        with self._lock:
            buffer.items.append(_Item(notification))
            if len(buffer.items) > 2 * self._capacity:
                cut = len(buffer.items) - self._capacity
                buffer.covered_after = buffer.items[cut - 1].notification.seq
                del buffer.items[:cut]
                buffer.base += cut
            if self._wake_pending or self._loop is None:
                return
            self._wake_pending = True
        with contextlib.suppress(RuntimeError):  # a closed loop: the server is stopping
            self._loop.call_soon_threadsafe(self._wake_soon)

    def _wake_soon(self) -> None:
        """On the loop: wake the clients once the coalescing window has passed."""
        assert self._loop is not None
        self._loop.call_later(COALESCE_SEC, self._wake)

    def _wake(self) -> None:
        with self._lock:
            self._wake_pending = False
        events, self._changed = self._changed, [asyncio.Event() for _ in range(WAKE_GROUPS)]
        self._set_from(events, 0)

    def _set_from(self, events: list[asyncio.Event], index: int) -> None:
        """Wake group ``index`` now and the next one on the loop's next turn."""
        events[index].set()
        if index + 1 < len(events):
            assert self._loop is not None
            self._loop.call_soon(self._set_from, events, index + 1)

    # -- client side (event loop) -----------------------------------------------------------
    def frame(self, item: _Item) -> bytes:
        if item.frame is None:
            notification = item.notification
            data = json.dumps(self._encode(notification), separators=(",", ":"))
            item.frame = (f"id: {notification.seq}\nevent: {notification.event_type.value}\n"
                          f"data: {data}\n\n").encode()
        return item.frame

    async def events(self, after: int | None) -> AsyncIterator[bytes]:
        """SSE bytes for one client: the notifications after seq ``after`` (None: from now),
        then live ones, each exactly once and in seq order. Keep-alive comments and noticing
        a closed connection are the response's job (sse-starlette)."""
        self.clients += 1
        try:
            sent = self._ledger.last_seq if after is None else after
            async for chunk in self._follow(sent):
                yield chunk
        finally:
            self.clients -= 1

    async def _follow(self, sent: int) -> AsyncIterator[bytes]:
        loop = asyncio.get_running_loop()
        group, self._next_group = self._next_group, (self._next_group + 1) % WAKE_GROUPS
        cursor: int | None = None
        while not self._stopped:
            if cursor is None:
                with self._lock:
                    covered = self._buffer.covered_after
                if sent < covered:
                    # Catching up from the log: the buffer does not reach back that far.
                    head = self._ledger.last_seq
                    page = await loop.run_in_executor(
                        None, self._ledger.notifications_after, sent, CATCH_UP_PAGE)
                    if page:
                        yield b"".join(self.frame(_Item(n)) for n in page)
                        sent = page[-1].seq
                    if len(page) < CATCH_UP_PAGE:
                        sent = max(sent, head)
                    continue
                cursor = self._index_after(sent)
            changed = self._changed[group] if self._changed else None
            frames, cursor, sent, fell_behind = self._take(cursor, sent)
            if fell_behind:
                self.dropped_clients += 1
                return
            if frames:
                yield frames
                continue
            assert changed is not None
            await changed.wait()

    def _index_after(self, sent: int) -> int:
        """Absolute index of the first buffered notification with a seq above ``sent``."""
        with self._lock:
            items, base = self._buffer.items, self._buffer.base
            low, high = 0, len(items)
            while low < high:
                middle = (low + high) // 2
                if items[middle].notification.seq <= sent:
                    low = middle + 1
                else:
                    high = middle
            return base + low

    def _take(self, cursor: int, sent: int) -> tuple[bytes, int, int, bool]:
        """The bytes of the buffered notifications from ``cursor`` on (those after ``sent``),
        the new cursor and seq, and whether the client fell off the buffer.

        Clients woken together are at the same cursor: the bytes from one to the buffer's end
        are joined once per wake-up for all of them (``_joined``), not once per client."""
        with self._lock:
            buffer = self._buffer
            if cursor < buffer.base:
                return b"", cursor, sent, True
            end = buffer.base + len(buffer.items)
            if cursor == end:
                return b"", cursor, sent, False
            newest = buffer.items[-1].notification.seq
            whole = buffer.items[cursor - buffer.base].notification.seq > sent
            joined = self._joined
            if whole and joined is not None and joined[0] == cursor and joined[1] == end:
                return joined[2], end, max(sent, newest), False
            ready = buffer.items[cursor - buffer.base:end - buffer.base]
        data = b"".join([self.frame(item) for item in ready if item.notification.seq > sent])
        if whole:
            self._joined = (cursor, end, data)
        return data, end, max(sent, newest), False
