"""`faultledger serve`: run the fault manager node until SIGINT/SIGTERM."""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading
import time
from types import FrameType

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from rclpy.utilities import (
    get_default_context,
    get_rmw_implementation_identifier,
    ok,
    try_shutdown,
)

from faultledger.alerts.deliverer import AlertDeliverer
from faultledger.domain.text import printable
from faultledger.errors import ConfigError
from faultledger.fleet.push import PusherThread
from faultledger.http.server import HttpServer
from faultledger.ros.bridges.runner import RunningBridge, settings_from, start_bridge
from faultledger.ros.dds_profile import use_manager_profile
from faultledger.ros.guard import clip, guard_callback
from faultledger.ros.network import scope
from faultledger.ros.node import NODE_NAME, FaultManagerNode, declare_policy
from faultledger.service.anchors import AnchorScheduler
from faultledger.service.bootstrap import Role, open_ledger, resolve
from faultledger.service.config import Settings
from faultledger.service.ledger import FaultLedger
from faultledger.service.policy_check import startup_warnings
from faultledger.startup_heap import freeze_startup_heap
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


def network_line(profile: str) -> str:
    """The ``fault_manager network:`` line printed before ``ready`` (docs/ros.md)."""
    domain_id = get_default_context().get_domain_id()
    return (f"fault_manager network: "
            f"{scope().describe(domain_id, get_rmw_implementation_identifier())} {profile}")


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


FOLLOWER_NAME = f"{NODE_NAME}_follower"
"""A read-only follower's node name: it coexists with the manager it follows."""
DISCOVERY_WAIT_SEC = 2.0
"""How long ``serve`` watches the ROS graph for another manager before serving.

Another ``serve`` announces itself every 0.5 s (dds_profile.py), so it shows up 4 times in this
window: measured on 2 cores, its ``report_fault`` appeared 0-0.43 s after our node was created
(12 starts).
A manager on Fast DDS's defaults announces every 3 s and is seen only if it announces within
the window (about 2 starts in 3); docs/ros.md "A second fault manager". The former 5 s,
sized for 3 s announcements, made every start of ``make run`` wait that long.
"""
ANSWER_WAIT_SEC = 5.0
"""How long a manager found in the graph has to answer ``list_faults`` before it is taken as
gone (killed with -9, still in the graph until its lease ends). Spent only when one is found."""
PROBE_RESEND_SEC = 1.0
"""How often ``answers`` sends its request again: a request sent before the other side has
matched our reply reader is dropped by it (rmw_fastrtps), and waiting longer will not help."""


def create_node(name: str = NODE_NAME) -> Node:
    """The ``/fault_manager`` node (``security_failure`` when it cannot be created)."""
    try:
        return Node(name)
    except Exception as error:
        raise security_failure("creating the node", error) from error


def other_manager(node: Node, follower: bool, wait_sec: float = DISCOVERY_WAIT_SEC
                  ) -> str | None:
    """Why ``node`` must not serve, or None: within ``wait_sec`` the graph shows another
    node of the same name, or someone already serving its ``report_fault`` (a follower's is
    ``/fault_manager_follower/report_fault``: only another follower serves it), and that
    other answers a request. Called before our services exist, so any server found is
    another."""
    fqn = node.get_fully_qualified_name()
    name, namespace = node.get_name(), node.get_namespace()
    service = f"{fqn}/report_fault"
    deadline = time.monotonic() + wait_sec
    while True:
        same = sum(1 for n, ns in node.get_node_names_and_namespaces()
                   if n == name and ns == namespace)
        served = any(s == service for s, _ in node.get_service_names_and_types())
        if same > 1 or served:
            break
        if time.monotonic() >= deadline:
            return None
        time.sleep(0.05)
    if not answers(node, f"{fqn}/list_faults"):
        return None  # a process killed with -9 stays in the graph until its lease expires
    what = f"serves {service}" if served else f"runs as {fqn}"
    other = fqn  # the service is <node>/report_fault; rcl does not say which process
    role = "fault manager follower" if follower else "fault manager"
    return (f"another {role} already {what} (node {other}, pid unknown); stop it, use "
            f"another namespace (--ros-args -r __ns:=/robot2)"
            + ("" if follower else ", or start this one as --follower"))


CHECK_DEADLINE_SEC = 20.0
"""Longest the check for another fault manager (and a refused start's teardown) may take."""


def _give_up(found: list[str]) -> None:
    """The watchdog of the start-up check: say why, and end the process (exit 2)."""
    why = found[0] if found else (
        f"could not finish checking the ROS graph for another fault manager within "
        f"{CHECK_DEADLINE_SEC:.0f} s (rclpy did not return); not serving")
    print(f"error: {printable(why)}", file=sys.stderr, flush=True)
    if not found and os.environ.get("FAULTLEDGER_DEBUG"):
        faulthandler.dump_traceback(file=sys.stderr)  # where rclpy hung
    sys.stdout.flush()
    os._exit(2)


def answers(node: Node, service: str, timeout_sec: float = ANSWER_WAIT_SEC) -> bool:
    """Whether someone answers a ``ListFaults`` on ``service`` within ``timeout_sec``: the
    request is sent again every ``PROBE_RESEND_SEC`` until one of them is answered."""
    from ros2_medkit_msgs.srv import ListFaults

    deadline = time.monotonic() + timeout_sec
    client = node.create_client(ListFaults, service)
    executor = SingleThreadedExecutor()  # our own, dropped before serving starts
    executor.add_node(node)
    futures: list[Future] = []
    try:
        if not client.wait_for_service(timeout_sec=timeout_sec):
            return False
        resend = 0.0
        while not any(f.done() for f in futures) and time.monotonic() < deadline:
            if time.monotonic() >= resend:
                futures.append(client.call_async(ListFaults.Request()))
                resend = time.monotonic() + PROBE_RESEND_SEC
            executor.spin_once(timeout_sec=0.05)
        return any(f.done() for f in futures)
    finally:
        for future in futures:
            if not future.done():
                client.remove_pending_request(future)
        executor.remove_node(node)
        # Bounded: shutdown() waits for work in flight, and a reply arriving after the
        # deadline leaves a task it would wait for forever.
        executor.shutdown(timeout_sec=1.0)
        node.destroy_client(client)


def serve(settings: Settings, db_url: str | None, ros_args: list[str],
          follower: bool = False, http_listen: str | None = None) -> int:
    """Serve until a signal; the database URL is --db, else ``database_path``, else config.

    ``follower``: a read-only follower (``fault_manager_follower``) on the same database:
    reads only, never writes (docs/ros.md "A second fault manager")."""
    role = Role.READER if follower else Role.SERVER
    # Before ROS starts: a bad database URL or shift calendar stops with its message.
    resolve(settings, role, db=db_url, shifts=settings.shifts)
    profile = use_manager_profile()
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
    print(network_line(profile), flush=True)
    try:
        node = create_node(FOLLOWER_NAME if follower else NODE_NAME)
    except BaseException:
        try_shutdown()
        raise
    # The check is bounded (DISCOVERY_WAIT_SEC, twice at most); the watchdog is a backstop
    # should rclpy not return: a start that cannot be checked must still end, with exit 2.
    found: list[str] = []
    watchdog = threading.Timer(CHECK_DEADLINE_SEC, _give_up, (found,))
    watchdog.daemon = True
    watchdog.start()
    try:
        refusal = other_manager(node, follower)
    except BaseException:
        watchdog.cancel()
        node.destroy_node()
        try_shutdown()
        raise
    if refusal is not None:
        # Said and ended here: nothing of ours needs cleaning up yet (no ledger is open), and
        # no DDS teardown can delay the exit.
        found.append(refusal)
        _give_up(found)
    watchdog.cancel()
    ledger: FaultLedger | None = None
    manager: FaultManagerNode | None = None
    bridges: list[RunningBridge] = []
    anchors: AnchorScheduler | None = None
    web: HttpServer | None = None
    pusher: PusherThread | None = None
    deliverer: AlertDeliverer | None = None
    executor = make_executor()
    try:
        node.declare_parameter("database_path", "")
        policy = declare_policy(node, settings.policy)
        path = str(node.get_parameter("database_path").value or "")
        config = resolve(settings, role, db=db_url, database_path=path,
                         policy=None if follower else policy, shifts=settings.shifts)
        url = config.url
        ledger = open_ledger(config)
        if not follower:  # where the policy in force makes a code's thresholds depend on the
            # reporting source (medkit #276); the manager a follower follows warns of its own
            for warning in startup_warnings(ledger):
                node.get_logger().warning(warning)
        # A follower writes nothing: no anchors, no bridges (the manager it follows runs them).
        anchors = None if follower else AnchorScheduler.from_settings(ledger, settings.anchors)
        if anchors is not None:
            anchors.start()  # an anchor file every interval, one more at shutdown
        leader = f"{node.get_namespace().rstrip('/')}/{NODE_NAME}"
        manager = FaultManagerNode(node, ledger, read_only=follower, leader=leader)
        executor.add_node(node)
        for name, entry in settings.bridges.items():
            if entry.get("enabled", False) and not follower:
                bridges.append(start_bridge(name, settings_from(entry), executor,
                                            manager=node.get_fully_qualified_name()))
        # The config's fleet: push this log to a central on a thread of its own, as `sync
        # --follow` does; a follower pushes nothing (the manager it follows does).
        pusher = None if follower else PusherThread.start_for(ledger, settings.fleet)
        # The config's alerts, delivered off the report path (docs/alerts.md); a follower
        # delivers nothing (the manager it follows does).
        deliverer = None if follower else AlertDeliverer.start_for(ledger, settings.alerts)
        if http_listen is not None:
            # The same ledger: one writer for ROS and HTTP (docs/http.md).
            web = HttpServer(ledger, settings.http, config.calendar, http_listen,
                             read_only=follower,
                             fleet_labels=settings.fleet.labels() if settings.fleet else None)
            web.start()
        freeze_startup_heap()  # before "ready": the collector skips all of the above
        restored = ledger.restored
        mode = f" follower of {leader} (read-only)" if follower else ""
        print(f"fault_manager ready: db={describe(url)} faults={restored.faults} "
              f"events={restored.events} replayed={restored.replayed}{mode}", flush=True)
        print(f"shifts: {config.calendar.summary()} "
              f"({settings.shifts or 'built-in default'}); "
              f"e-stops: {', '.join(config.estop_codes)}", flush=True)
        if web is not None:
            print(f"http ready: dashboard {web.url} API {web.url}docs; {web.access}",
                  flush=True)
        if pusher is not None:
            print(pusher.describe, flush=True)
        if deliverer is not None:
            print(printable(deliverer.describe), flush=True)
        node.get_logger().info(
            f"serving {node.get_fully_qualified_name()}{mode} on {describe(url)}: restored "
            f"{restored.faults} faults from {restored.events} events")
        spin_until(executor, stop)
        if manager is not None:
            drain_reads(executor, manager)
    finally:
        if deliverer is not None:
            deliverer.stop()
        if pusher is not None:
            pusher.stop()
        if web is not None:
            web.stop()
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
