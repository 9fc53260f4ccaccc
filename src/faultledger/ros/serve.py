"""`faultledger serve`: run the fault manager node until SIGINT/SIGTERM."""

from __future__ import annotations

import signal
import threading
from types import FrameType

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import ok, try_shutdown

from faultledger.ros.bridges.runner import RunningBridge, settings_from, start_bridge
from faultledger.ros.node import NODE_NAME, FaultManagerNode, declare_policy
from faultledger.service.config import Settings, load_shift_calendar
from faultledger.service.ledger import FaultLedger
from faultledger.store.database import describe


def make_executor() -> SingleThreadedExecutor:
    """The fault manager's executor (bench/ros_report.py measures its echo baseline with it).

    Single-threaded: reports queued during a commit are taken together by the next callback
    (service_queue.py), which shares fsyncs without the per-call cost of rclpy's
    multi-threaded executor (bench/ros_report.py; docs/performance.md).
    """
    return SingleThreadedExecutor()


def spin_until(executor: SingleThreadedExecutor, stop: threading.Event) -> None:
    """Serve callbacks until ``stop`` is set or the context shuts down."""
    while not stop.is_set() and ok():
        executor.spin_once(timeout_sec=0.1)


def serve(settings: Settings, db_url: str | None, ros_args: list[str]) -> int:
    """Serve until a signal; the database URL is --db, else ``database_path``, else config."""
    # Before ROS starts: a bad shift calendar stops the manager with the file's message.
    calendar = None if settings.shifts is None else load_shift_calendar(settings.shifts)
    rclpy.init(args=["faultledger", *ros_args],
               signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()

    def on_signal(_signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    node = Node(NODE_NAME)
    ledger: FaultLedger | None = None
    manager: FaultManagerNode | None = None
    bridges: list[RunningBridge] = []
    executor = make_executor()
    try:
        node.declare_parameter("database_path", "")
        policy = declare_policy(node, settings.policy)
        path = str(node.get_parameter("database_path").value or "")
        url = db_url or (f"sqlite:///{path}" if path else settings.database.url)
        ledger = FaultLedger.open(url, policy=policy, max_batch=settings.database.max_batch,
                                  calendar=calendar)
        manager = FaultManagerNode(node, ledger)
        executor.add_node(node)
        for name, entry in settings.bridges.items():
            if entry.get("enabled", False):
                bridges.append(start_bridge(name, settings_from(entry), executor,
                                            manager=node.get_fully_qualified_name()))
        restored = ledger.restored
        print(f"fault_manager ready: db={describe(url)} faults={restored.faults} "
              f"events={restored.events} replayed={restored.replayed}", flush=True)
        node.get_logger().info(
            f"serving {node.get_fully_qualified_name()} on {describe(url)}: restored "
            f"{restored.faults} faults from {restored.events} events")
        spin_until(executor, stop)
    finally:
        for bridge in bridges:
            bridge.close()
        if manager is not None:
            manager.close()
        executor.shutdown()
        if ledger is not None:
            ledger.close()
        node.destroy_node()
        try_shutdown()
    return 0
