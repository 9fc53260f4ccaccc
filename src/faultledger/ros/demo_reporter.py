"""The demo reporter of `make run`: a node that reports a few faults through FaultReporter."""

from __future__ import annotations

import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import try_shutdown
from ros2_medkit_msgs.srv import ListFaults

from faultledger.domain.types import Severity
from faultledger.ros.reporter import FaultReporter

SOURCE = "/demo/drive_controller"
SCRIPT: list[tuple[str, str, int]] = [
    ("FAILED", "DEMO_WHEEL_SLIP", Severity.WARN),      # filtered locally (1 of 3)
    ("FAILED", "DEMO_WHEEL_SLIP", Severity.WARN),      # filtered locally (2 of 3)
    ("FAILED", "DEMO_WHEEL_SLIP", Severity.WARN),      # third within 10 s: forwarded
    ("FAILED", "DEMO_MOTOR_OVERHEAT", Severity.ERROR),  # ERROR bypasses the filter
    ("FAILED", "DEMO_ESTOP_PRESSED", Severity.CRITICAL),
]


def spin_until(executor: SingleThreadedExecutor, done: object, timeout: float) -> bool:
    """spin_once loop (never repeated spin_until_future_complete: rclpy 7.1.6 slows down)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if callable(done) and done():
            return True
        executor.spin_once(timeout_sec=0.05)
    return bool(callable(done) and done())


def main() -> int:
    rclpy.init()
    node = Node("demo_reporter")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    reporter = FaultReporter(node, SOURCE)
    try:
        for kind, code, severity in SCRIPT:
            sent = (reporter.report(code, severity, f"demo: {code.lower()}") if kind == "FAILED"
                    else reporter.report_passed(code))
            print(f"  {kind} {code} ({Severity(severity).name}): "
                  f"{'sent' if sent else 'filtered locally'}")
        if not spin_until(executor, lambda: reporter.pending == 0, 30.0):
            print("demo reporter: the fault manager did not answer in 30 s", file=sys.stderr)
            return 1
        client = node.create_client(ListFaults, "/fault_manager/list_faults")
        client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(ListFaults.Request(statuses=["CONFIRMED", "PREFAILED"]))
        spin_until(executor, future.done, 10.0)
        print("  /fault_manager/list_faults (CONFIRMED, PREFAILED):")
        for fault in future.result().faults:
            print(f"    {fault.fault_code:<24} {fault.status:<10} severity {fault.severity} "
                  f"from {', '.join(fault.reporting_sources)}")
        return 0
    finally:
        reporter.destroy()
        node.destroy_node()
        try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
