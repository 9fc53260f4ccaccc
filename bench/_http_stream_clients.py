"""N SSE clients in one asyncio process, for bench/http_api.py: each records the receive time of
every event id. Usage: _http_stream_clients.py URL N SECONDS OUT.json
Prints "connected" once every client has its stream open, then reads the last seq sent from
stdin: each client stops once it has that id, or SECONDS after it was given (a real loss).

The clients are the measuring instrument, and they share the machine with the server: each is
a bare asyncio protocol on its socket (one callback per read, the ids found by one regular
expression over the bytes as received) rather than an HTTP client library, whose layers per
read made this process fall seconds behind the server it measures (docs/performance.md).
The stream's chunked framing needs no decoding for that: the server writes whole SSE blocks
per chunk, so a chunk-size line never falls inside an ``id:`` line, and those lines are all
that is read.
"""

from __future__ import annotations

import asyncio
import gc
import json
import re
import sys
import time
from array import array
from collections.abc import Callable
from functools import partial
from urllib.parse import urlsplit

ID = re.compile(rb"\nid: (\d+)\n")
r"""An ``id:`` line. A literal first byte lets the regular expression engine skip ahead: ten
times the speed of ``^id: (\d+)$`` in MULTILINE mode, which tries every byte (~20 % of a core
at the 34 MB/s that 100 clients receive)."""
PATH = "/api/v1/faults/stream"


class Received:
    """Ids and receive times in flat arrays: millions of tuples would make the garbage
    collector's full scans (pauses of 100 ms and more) part of the measured latency."""

    def __init__(self) -> None:
        self.ids = array("q")
        self.times = array("d")


class StreamClient(asyncio.Protocol):
    """One GET of the stream; every ``id:`` of a whole SSE block is recorded with the time
    its bytes arrived."""

    def __init__(self, request: bytes, received: Received, opened: Callable[[], None]) -> None:
        self.request = request
        self.received = received
        self.opened = opened
        self.in_body = False
        self.rest = b""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.WriteTransport)
        transport.write(self.request)

    def data_received(self, data: bytes) -> None:
        now = time.time()
        text = self.rest + data
        if not self.in_body:
            end = text.find(b"\r\n\r\n")
            if end < 0:
                self.rest = text
                return
            status = text[:text.find(b"\r\n")]
            if not status.startswith(b"HTTP/1.1 200 "):
                raise RuntimeError(f"the stream answered {status!r}")
            self.in_body = True
            self.opened()
            text = b"\n" + text[end + 4:]
        end = text.rfind(b"\n\n")
        if end < 0:  # no whole block yet (a TCP segment inside one): wait for more
            self.rest = text
            return
        ids, times = self.received.ids, self.received.times
        for found in ID.findall(text, 0, end + 2):  # whole blocks only
            ids.append(int(found))
            times.append(now)
        self.rest = text[end + 1:]  # from the block end's last newline, which ID starts with


async def main(url: str, count: int, seconds: float, out: str) -> None:
    parts = urlsplit(url)
    host, port = parts.hostname or "127.0.0.1", parts.port or 80
    request = (f"GET {PATH} HTTP/1.1\r\nHost: {host}:{port}\r\n"
               "Accept: text/event-stream\r\n\r\n").encode()
    results = [Received() for _ in range(count)]
    opened = asyncio.Event()
    streams = [0]

    def one_open() -> None:
        streams[0] += 1
        if streams[0] == count:
            opened.set()

    loop = asyncio.get_running_loop()
    transports: list[asyncio.Transport] = []
    for received in results:
        transport, _ = await loop.create_connection(
            partial(StreamClient, request, received, one_open), host, port)
        transports.append(transport)
    await asyncio.wait_for(opened.wait(), 30)
    print("connected", flush=True)
    line = await loop.run_in_executor(None, sys.stdin.readline)
    last, until = int(line), time.time() + seconds
    while time.time() < until and not all(r.ids and r.ids[-1] >= last for r in results):
        await asyncio.sleep(0.1)
    for opened_transport in transports:
        opened_transport.close()
    with open(out, "w") as file:
        json.dump([list(zip(r.ids, r.times, strict=True)) for r in results], file)


if __name__ == "__main__":
    gc.freeze()  # the objects made so far are never collected: smaller scans
    asyncio.run(main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]))
