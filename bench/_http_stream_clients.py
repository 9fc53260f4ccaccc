"""N SSE clients in one asyncio process, for bench/http_api.py: each records the receive time of
every event id. Usage: _http_stream_clients.py URL N SECONDS OUT.json
Prints "connected" once every client has its stream open, then reads the last seq sent from
stdin: each client stops once it has that id, or SECONDS after it was given (a real loss)."""

from __future__ import annotations

import asyncio
import gc
import json
import re
import sys
import time
from array import array

import httpx

ID = re.compile(rb"^id: (\d+)$", re.MULTILINE)


class Received:
    """Ids and receive times in flat arrays: millions of tuples would make the garbage
    collector's full scans (pauses of 100 ms and more) part of the measured latency."""

    def __init__(self) -> None:
        self.ids = array("q")
        self.times = array("d")


async def client(http: httpx.AsyncClient, received: Received,
                 opened: asyncio.Event, counter: list[int], total: int) -> None:
    async with http.stream("GET", "/api/v1/faults/stream") as response:
        counter[0] += 1
        if counter[0] == total:
            opened.set()
        rest = b""
        async for chunk in response.aiter_bytes():
            now = time.time()
            text = rest + chunk
            end = text.rfind(b"\n\n")
            if end < 0:  # no whole block yet (a TCP segment inside one): wait for more
                rest = text
                continue
            cut = end + 2  # whole blocks only; the rest waits for more
            for found in ID.findall(text[:cut]):
                received.ids.append(int(found))
                received.times.append(now)
            rest = text[cut:]


async def main(url: str, count: int, seconds: float, out: str) -> None:
    limits = httpx.Limits(max_connections=count + 5, max_keepalive_connections=count + 5)
    results = [Received() for _ in range(count)]
    opened = asyncio.Event()
    counter = [0]
    async with httpx.AsyncClient(base_url=url, limits=limits,
                                 timeout=httpx.Timeout(10, read=None)) as http:
        tasks = [asyncio.create_task(client(http, results[i], opened, counter, count))
                 for i in range(count)]
        await asyncio.wait_for(opened.wait(), 30)
        print("connected", flush=True)
        line = await asyncio.get_running_loop().run_in_executor(None, sys.stdin.readline)
        last, until = int(line), time.time() + seconds
        while time.time() < until and not all(r.ids and r.ids[-1] >= last for r in results):
            await asyncio.sleep(0.1)
        for task in tasks:
            task.cancel()
    with open(out, "w") as file:
        json.dump([list(zip(r.ids, r.times, strict=True)) for r in results], file)


if __name__ == "__main__":
    gc.freeze()  # the objects made so far are never collected: smaller scans
    asyncio.run(main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]))
