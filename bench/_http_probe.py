"""The bench's interactive client: GET /api/v1/faults every 20 ms over one keep-alive
connection for SECONDS, in a process of its own (the load's client threads would otherwise
share its GIL); prints the latencies in seconds as JSON. Usage: _http_probe.py URL SECONDS"""

from __future__ import annotations

import json
import sys
import time

import httpx

url, seconds = sys.argv[1], float(sys.argv[2])
latencies: list[float] = []
failures = 0
with httpx.Client(base_url=url, timeout=30) as client:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        started = time.perf_counter()
        if client.get("/api/v1/faults").status_code != 200:
            failures += 1
        latencies.append(time.perf_counter() - started)
        time.sleep(0.02)
print(json.dumps({"latencies": latencies, "failures": failures}), flush=True)
