"""`faultledger serve --http`: the ROS node and the HTTP API in one process over one ledger.
A report made over ROS is in the HTTP list and stream; one posted over HTTP is in get_fault."""

from __future__ import annotations

import re
import time
from typing import TYPE_CHECKING

import httpx

if TYPE_CHECKING:
    from tests.ros.conftest import ManagerFactory, RosClient

URL = re.compile(r"http ready: dashboard (http://127\.0\.0\.1:\d+/)")


def test_ros_and_http_share_one_ledger(manager: ManagerFactory, client: RosClient) -> None:
    served = manager("--http", "127.0.0.1:0")
    deadline = time.monotonic() + 10
    found = None
    while found is None and time.monotonic() < deadline:
        found = next((URL.search(line) for line in served.stdout_lines if URL.search(line)),
                     None)
        time.sleep(0.05)
    assert found is not None, served.describe()
    with httpx.Client(base_url=found.group(1), timeout=10) as web, web.stream(
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
