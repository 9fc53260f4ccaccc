"""A get_statistics caller in its own process, driven over stdin (tests/ros/test_read_pool.py).

``python drive_stats.py`` prints ``ready`` once ``/fault_manager/get_statistics`` is available,
then reads one JSON object per line (GetStatistics.Request fields: ``by``, ``since``,
``until``, ``codes``, ``group_by``) and answers one line
``stats {"success": ..., "message": ..., "rows": N, "seconds": S}`` (``seconds``: from the
call to the answer, measured here). EOF or ``exit`` ends it. Its own process: receiving a big
answer must not hold up the test process's GIL while the test measures report latencies.
"""

from __future__ import annotations

import json
import sys
import time


def main() -> int:
    import rclpy
    from faultledger_msgs.srv import GetStatistics
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    context = Context()
    rclpy.init(args=sys.argv, context=context)
    node = rclpy.create_node("pytest_drive_stats", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                     reliability=ReliabilityPolicy.RELIABLE)
    client = node.create_client(GetStatistics, "/fault_manager/get_statistics", qos_profile=qos)
    try:
        if not client.wait_for_service(timeout_sec=20.0):
            print("no get_statistics service", file=sys.stderr, flush=True)
            return 2
        print("ready", flush=True)
        for line in sys.stdin:
            if not line.strip() or line.strip() == "exit":
                break
            fields = json.loads(line)
            request = GetStatistics.Request(**fields)
            start = time.monotonic()
            future = client.call_async(request)
            while not future.done():
                executor.spin_once(timeout_sec=0.05)
                if time.monotonic() - start > 120.0:
                    print("no answer within 120 s", file=sys.stderr, flush=True)
                    return 3
            seconds = time.monotonic() - start
            response = future.result()
            print("stats", json.dumps({"success": response.success, "message": response.message,
                                       "rows": len(response.rows), "seconds": seconds}),
                  flush=True)
        return 0
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
