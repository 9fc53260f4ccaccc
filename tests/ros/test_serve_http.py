"""`faultledger serve --http`: the ROS node and the HTTP API in one process over one ledger.
A report made over ROS is in the HTTP list and stream; one posted over HTTP is in get_fault.
Heavy statistics requests over HTTP never hold up the ROS node's reports."""

from __future__ import annotations

import re
import threading
import time
from typing import TYPE_CHECKING, Any

import httpx

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

URL = re.compile(r"http ready: dashboard (http://127\.0\.0\.1:\d+/)")


HEAVIEST = "/api/v1/stats?by=10min&since=2026-01-01T00:00Z&until=2026-03-11T09:00Z"
"""9,990 periods: the largest statistics answer the HTTP API allows (http.max_stats_rows)."""


def http_url(served: Any) -> str:
    deadline = time.monotonic() + 10
    found = None
    while found is None and time.monotonic() < deadline:
        found = next((URL.search(line) for line in served.stdout_lines if URL.search(line)),
                     None)
        time.sleep(0.05)
    assert found is not None, served.describe()
    return found.group(1)


def test_ros_and_http_share_one_ledger(manager: ManagerFactory, client: RosClient) -> None:
    served = manager("--http", "127.0.0.1:0")
    with httpx.Client(base_url=http_url(served), timeout=10) as web, web.stream(
            "GET", "/api/v1/faults/stream") as stream:
        assert client.report("ROS_SIDE", 0, 3, "from ROS", "/ros/node")
        lines = stream.iter_lines()
        event = next(line for line in lines if line.startswith("event:"))
        assert event == "event: fault_confirmed"
        assert next(lines).startswith('data: {"event_type":"fault_confirmed","fault":'
                                      '{"description":"from ROS","fault_code":"ROS_SIDE"')
        listed = web.get("/api/v1/faults").json()["items"]
        assert [i["fault_code"] for i in listed] == ["ROS_SIDE"]
        answer = web.post("/api/v1/reports", json={"fault_code": "HTTP_SIDE",
                                                   "event_type": "FAILED", "severity": 3,
                                                   "source_id": "/plc"}).json()
        assert answer["accepted"], answer
        assert client.fault("HTTP_SIDE").status == "CONFIRMED"
    assert served.stop() == 0


def test_heavy_http_reads_never_hold_up_ros_reports(manager: ManagerFactory,
                                                    client: RosClient) -> None:
    served = manager("--http", "127.0.0.1:0")
    url = http_url(served)
    codes: list[int] = []

    def heavy() -> None:
        with httpx.Client(base_url=url, timeout=60) as web:
            codes.append(web.get(HEAVIEST).status_code)

    readers = [threading.Thread(target=heavy) for _ in range(12)]
    for reader in readers:
        reader.start()
    waits = []
    with httpx.Client(base_url=url, timeout=10) as web:
        for number in range(20):  # while the heavy reads are computed and queued
            started = time.monotonic()
            assert client.report(f"ROS_UNDER_LOAD_{number:02d}", 0, 2, "", "/ros/node")
            waits.append(time.monotonic() - started)
            assert web.get("/api/v1/faults").status_code == 200
            time.sleep(0.2)
    for reader in readers:
        reader.join(90)
    assert len(codes) == 12 and set(codes) <= {200, 503} and 200 in codes, codes
    # Generous: the 2 cores are shared with the test's own clients.
    assert max(waits) < 3.0, waits
    assert served.stop() == 0
