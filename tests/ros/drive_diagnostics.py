"""A diagnostics publisher process for the bridge tests: like a diagnostic_updater, it publishes
its current DiagnosticArray on /diagnostics periodically, and takes orders on stdin.

stdin, one JSON object per line:

* ``{"set": [status, ...]}``: the array to publish from now on (published at once); answers
  ``set <n>`` with n = how many times the array was published so far. A status is
  ``{"name", "level" (int, sent as one byte, so 7 works too), "message", "hardware_id",
  "values": {key: value}}``, all optional.
* ``{"ticks": n}``: answers ``ticked`` once the current array was published n more times.

stdout: ``matched`` once a subscriber is matched, then the answers above. argv[1]: the period
in seconds (default 0.2). EOF on stdin ends the process.
"""

from __future__ import annotations

import json
import os
import select
import sys
import time
from typing import Any

import rclpy
from diagnostic_msgs.msg import (  # type: ignore[import-untyped,unused-ignore]
    DiagnosticArray,
    DiagnosticStatus,
    KeyValue,
)
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy


def build(statuses: list[dict[str, Any]]) -> Any:
    array = DiagnosticArray()
    for s in statuses:
        array.status.append(DiagnosticStatus(
            level=bytes([int(s.get("level", 0))]), name=s.get("name", ""),
            message=s.get("message", ""), hardware_id=s.get("hardware_id", ""),
            values=[KeyValue(key=k, value=v) for k, v in s.get("values", {}).items()]))
    return array


def main() -> int:
    period = float(sys.argv[1]) if len(sys.argv) > 1 else 0.2
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node(f"test_diagnostics_publisher_{os.getpid()}", context=context)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    publisher = node.create_publisher(DiagnosticArray, "/diagnostics", qos)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    current = DiagnosticArray()
    published = 0
    tick_target: int | None = None
    matched = False
    next_at = time.monotonic()
    try:
        while True:
            executor.spin_once(timeout_sec=0.01)
            if not matched and publisher.get_subscription_count() > 0:
                matched = True
                print("matched", flush=True)
            now = time.monotonic()
            if now >= next_at:
                current.header.stamp = node.get_clock().now().to_msg()
                publisher.publish(current)
                published += 1
                next_at = now + period
            if tick_target is not None and published >= tick_target:
                print("ticked", flush=True)
                tick_target = None
            if select.select([sys.stdin], [], [], 0)[0]:
                line = sys.stdin.readline()
                if not line:
                    return 0
                order = json.loads(line)
                if "set" in order:
                    current = build(order["set"])
                    publisher.publish(current)
                    published += 1
                    next_at = time.monotonic() + period
                    print(f"set {published}", flush=True)
                if "ticks" in order:
                    tick_target = published + int(order["ticks"])
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
