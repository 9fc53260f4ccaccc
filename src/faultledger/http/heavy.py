"""Heavy reads (statistics, history, state-at, the shift report) in a small pool of their own
(docs/http.md, "Limits").

At most ``slots`` of them compute at once, each on a thread of the pool, so however many
arrive, the CPU and memory they take are bounded, and reports, the fault list, the event
stream and a ROS node in the same process keep their share. A request waiting for a slot is a
coroutine on the event loop and holds no thread. The queue is short: one more waiter than
``queue``, or a wait longer than ``wait_sec``, is answered 503 ``unavailable`` with
``Retry-After``.

An answer is sent while its slot is held (``SlotResponse``): its rows are turned into bytes a
chunk at a time, on the pool, and the next chunk is made only once the client took the last
one. So no more than ``slots`` answers are ever in memory, however slowly clients read; a
client that reads nothing is cut off by the connection's send timeout (connections.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
from collections.abc import AsyncIterator, Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import Any, TypeVar

from starlette.responses import Response
from starlette.types import Receive, Scope, Send

from faultledger.errors import Reason
from faultledger.http.errors import ApiError

T = TypeVar("T")
Chunks = Iterator[bytes]


class HeavyReads:
    def __init__(self, slots: int, queue: int, wait_sec: float, *,
                 what: str = "heavy reads (statistics, history, state-at, shift report)",
                 settings: str = "http.heavy_reads {slots}, http.heavy_queue {queue}") -> None:
        self.what = what
        self.settings = settings
        self.slots = slots
        self.queue = queue
        self.wait_sec = wait_sec
        self._free = asyncio.Semaphore(slots)
        self._executor = ThreadPoolExecutor(slots, thread_name_prefix="faultledger-heavy")
        self.running = 0
        self.waiting = 0
        self.refused = 0
        self._seconds = 1.0
        """A running mean of how long a slot is held, for Retry-After."""

    def close(self) -> None:
        self._executor.shutdown(wait=False, cancel_futures=True)

    @contextlib.asynccontextmanager
    async def slot(self, *, may_refuse: bool = True) -> AsyncIterator[None]:
        """Hold one of the slots; ``may_refuse``: answer 503 when the queue is full or the
        wait too long (False: the next chunk of an answer already being sent waits)."""
        if may_refuse and self._free.locked() and self.waiting >= self.queue:
            self._refuse()
        self.waiting += 1
        try:
            if may_refuse:
                try:
                    async with asyncio.timeout(self.wait_sec):
                        await self._free.acquire()
                except TimeoutError:
                    self._refuse()
            else:
                await self._free.acquire()
        finally:
            self.waiting -= 1
        self.running += 1
        started = time.monotonic()
        try:
            yield
        finally:
            self.running -= 1
            self._seconds = 0.8 * self._seconds + 0.2 * (time.monotonic() - started)
            self._free.release()

    def _refuse(self) -> None:
        self.refused += 1
        after = max(1, min(60, math.ceil(self._seconds * (self.waiting + 1) / self.slots)))
        settings = self.settings.format(slots=self.slots, queue=self.queue)
        raise ApiError(Reason.UNAVAILABLE,
                       f"busy: {self.running} {self.what} are being computed and "
                       f"{self.waiting} wait ({settings}); retry in {after} s",
                       {"Retry-After": str(after)})

    async def call(self, work: Callable[..., T], *args: Any) -> T:
        """``work(*args)`` on one of the pool's threads (the caller holds a slot)."""
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._executor, partial(work, *args))


class SlotResponse(Response):
    """An answer made in the heavy pool: ``produce()`` (run on the pool) does the work and
    returns the body's chunks, each made on the pool when the one before was sent.

    The slot is taken when the response is sent, and held until its last byte is. An error
    before the first chunk (a refused query, a 503 for a full queue) is raised before the
    response starts, so it is answered as JSON like any other. ``per_chunk``: a long export
    takes a slot for each chunk only (other heavy reads go between), and its first chunk
    alone may be refused 503."""

    def __init__(self, heavy: HeavyReads, produce: Callable[[], Chunks], media_type: str,
                 headers: dict[str, str] | None = None, *, per_chunk: bool = False) -> None:
        # As StreamingResponse: no body yet, so no content-length (chunked).
        self.status_code = 200
        self.media_type = media_type
        self.background = None
        self.init_headers(headers)
        self.heavy = heavy
        self.produce = produce
        self.per_chunk = per_chunk

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        heavy = self.heavy
        async with heavy.slot():
            chunks = await heavy.call(self.produce)
            chunk = await heavy.call(next, chunks, None)
            await send({"type": "http.response.start", "status": self.status_code,
                        "headers": self.raw_headers})
            if not self.per_chunk:
                await self._send_all(send, chunks, chunk)
                return
        await self._send_all(send, chunks, chunk, per_chunk=True)

    async def _send_all(self, send: Send, chunks: Chunks, chunk: bytes | None, *,
                        per_chunk: bool = False) -> None:
        """Send ``chunk`` and the rest of ``chunks``, making the next one while nothing is
        in flight; the last message says so (an empty body is one empty message)."""
        heavy = self.heavy
        while True:
            following = None
            if chunk is not None:
                if per_chunk:
                    async with heavy.slot(may_refuse=False):
                        following = await heavy.call(next, chunks, None)
                else:
                    following = await heavy.call(next, chunks, None)
            await send({"type": "http.response.body", "body": chunk or b"",
                        "more_body": following is not None})
            if following is None:
                return
            chunk = following


def json_bytes(value: Any) -> bytes:
    """Compact JSON, as Starlette's JSONResponse writes it."""
    return json.dumps(value, ensure_ascii=False, allow_nan=False,
                      separators=(",", ":")).encode()


def json_items(rows: list[T], encode: Callable[[T], Any], extra: dict[str, Any] | None = None,
               chunk: int = 500) -> Chunks:
    """``{"items": [...], **extra}`` as compact JSON, ``chunk`` rows per piece."""
    dumps = json.JSONEncoder(separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode
    yield b'{"items":['
    for start in range(0, len(rows), chunk):
        text = ",".join(dumps(encode(row)) for row in rows[start:start + chunk])
        yield (text if start == 0 else "," + text).encode()
    tail = "".join(f",{dumps(key)}:{dumps(value)}" for key, value in (extra or {}).items())
    yield f"]{tail}}}".encode()
