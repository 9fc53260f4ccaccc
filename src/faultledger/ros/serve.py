"""`faultledger serve`: run the fault manager node until SIGINT/SIGTERM."""

from __future__ import annotations

import signal
import threading
import time
from types import FrameType

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import (
    get_default_context,
    get_rmw_implementation_identifier,
    ok,
    try_shutdown,
)

from faultledger.errors import ConfigError
from faultledger.ros.bridges.runner import RunningBridge, settings_from, start_bridge
from faultledger.ros.guard import clip, guard_callback
from faultledger.ros.network import scope
from faultledger.ros.node import NODE_NAME, FaultManagerNode, declare_policy
from faultledger.service.anchors import AnchorScheduler
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


READ_DRAIN_SEC = 10.0
"""At shutdown, how long reads still computing may take to be answered."""
ANSWER_GRACE_SEC = 0.2
"""After the last of them: time for the middleware to send the answers."""


def spin_until(executor: SingleThreadedExecutor, stop: threading.Event) -> None:
    """Serve callbacks until ``stop`` is set or the context shuts down.

    Our callbacks never raise (guard.py); an exception from rclpy's own steps around them
    (e.g. converting a response) is logged like theirs and serving goes on."""
    spin_once = guard_callback(executor.spin_once, get_logger("faultledger.serve"), "executor")
    while not stop.is_set() and ok():
        spin_once(0.1)


def drain_reads(executor: SingleThreadedExecutor, manager: FaultManagerNode,
                timeout: float = READ_DRAIN_SEC) -> None:
    """Keep spinning until the reads handed to the pool are answered (or ``timeout``), then
    a little longer so the middleware sends those answers before the service is destroyed."""
    if not manager.reads.in_flight:
        return
    deadline = time.monotonic() + timeout
    spin_once = guard_callback(executor.spin_once, get_logger("faultledger.serve"), "executor")
    while manager.reads.in_flight and time.monotonic() < deadline and ok():
        spin_once(0.1)
    grace = time.monotonic() + ANSWER_GRACE_SEC
    while time.monotonic() < grace and ok():
        spin_once(0.05)


def network_line() -> str:
    """The ``fault_manager network:`` line printed before ``ready`` (docs/ros.md)."""
    domain_id = get_default_context().get_domain_id()
    return (f"fault_manager network: "
            f"{scope().describe(domain_id, get_rmw_implementation_identifier())}")


def security_failure(step: str, error: Exception) -> Exception:
    """``error`` of ``step`` as it is, or, when ROS security is on (the usual cause), a
    ConfigError that says so (docs/ros.md "Network scope and security")."""
    if not scope().security:
        return error
    return ConfigError(
        f"ROS_SECURITY_ENABLE=true, but {step} failed: {clip(str(error), 300)}. SROS2 needs a "
        "keystore with an enclave for this process (ROS_SECURITY_KEYSTORE) and an RMW built "
        "with security; the Fast DDS of the ROS 2 wheels from PyPI is built without it (see "
        "docs/ros.md, 'Network scope and security')")


def create_node() -> Node:
    """The ``/fault_manager`` node (``security_failure`` when it cannot be created)."""
    try:
        return Node(NODE_NAME)
    except Exception as error:
        raise security_failure("creating the node", error) from error


def serve(settings: Settings, db_url: str | None, ros_args: list[str]) -> int:
    """Serve until a signal; the database URL is --db, else ``database_path``, else config."""
    # Before ROS starts: a bad shift calendar stops the manager with the file's message.
    calendar = None if settings.shifts is None else load_shift_calendar(settings.shifts)
    try:
        rclpy.init(args=["faultledger", *ros_args],
                   signal_handler_options=SignalHandlerOptions.NO)
    except Exception as error:
        raise security_failure("starting ROS (rclpy.init)", error) from error
    stop = threading.Event()

    def on_signal(_signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    print(network_line(), flush=True)
    try:
        node = create_node()
    except BaseException:
        try_shutdown()
        raise
    ledger: FaultLedger | None = None
    manager: FaultManagerNode | None = None
    bridges: list[RunningBridge] = []
    anchors: AnchorScheduler | None = None
    executor = make_executor()
    try:
        node.declare_parameter("database_path", "")
        policy = declare_policy(node, settings.policy)
        path = str(node.get_parameter("database_path").value or "")
        url = db_url or (f"sqlite:///{path}" if path else settings.database.url)
        ledger = FaultLedger.open(url, policy=policy, max_batch=settings.database.max_batch,
                                  calendar=calendar)
        anchors = AnchorScheduler.from_settings(ledger, settings.anchors)
        if anchors is not None:
            anchors.start()  # an anchor file every interval, one more at shutdown
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
        if manager is not None:
            drain_reads(executor, manager)
    finally:
        for bridge in bridges:
            bridge.close()
        if manager is not None:
            manager.close()
        executor.shutdown()
        if anchors is not None:
            anchors.stop()
        if ledger is not None:
            ledger.close()
        node.destroy_node()
        try_shutdown()
    return 0
