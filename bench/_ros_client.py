"""One client process of bench/ros_report.py: sequential ReportFault calls, latencies as JSON.

The client pattern of FaultReporter and the ROS tests: ``call_async`` then ``spin_once`` until
the future is done (never a repeated spin_until_future_complete, ros-wheels.md §8). It waits
for the service, then for a line on stdin, so that every client of a run starts together.
An answer that has not come after ANSWER_TIMEOUT_S is counted as lost and the client goes on
(once, in a four-client warm-up right after discovery, a client waited ten minutes for one
answer while the server had committed all its reports: docs/performance.md, tenth round).
"""

from __future__ import annotations

import json
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.utilities import try_shutdown
from ros2_medkit_msgs.srv import ReportFault

ANSWER_TIMEOUT_S = 10.0


def main() -> None:
    calls, client_no, codes = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
    rclpy.init()
    node = Node(f"bench_client_{client_no}")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    client = node.create_client(ReportFault, "/fault_manager/report_fault",
                                qos_profile=QoSProfile(depth=1000,
                                                       reliability=ReliabilityPolicy.RELIABLE))
    if not client.wait_for_service(timeout_sec=30.0):
        sys.exit("bench client: /fault_manager/report_fault did not appear within 30 s")
    print("ready", flush=True)
    sys.stdin.readline()
    source = f"/bench/client{client_no}"
    latencies: list[float] = []
    rejected = 0
    lost = 0
    start = time.perf_counter()
    for i in range(calls):
        request = ReportFault.Request(
            fault_code=f"BENCH_{client_no}_{i % codes:04d}", event_type=i // codes % 2,
            severity=2, description="bench", source_id=source)
        sent = time.perf_counter()
        future = client.call_async(request)
        while not future.done() and time.perf_counter() - sent < ANSWER_TIMEOUT_S:
            executor.spin_once(timeout_sec=1.0)
        if not future.done():
            client.remove_pending_request(future)
            lost += 1
            continue
        latencies.append(time.perf_counter() - sent)
        rejected += not future.result().accepted
    elapsed = time.perf_counter() - start
    print(json.dumps({"elapsed": elapsed, "rejected": rejected, "lost": lost,
                      "latencies": latencies}),
          flush=True)
    node.destroy_node()
    try_shutdown()


if __name__ == "__main__":
    main()
