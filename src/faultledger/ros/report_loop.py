"""The report services, served on a thread of their own instead of by the executor.

rclpy's executor rebuilds its wait set from every entity of the node and runs each callback
as a task on every turn: per call that costs more Python than a report's own CPU once the
ledger is compiled, and with several clients it is the executor's CPU that runs out
(bench/ros_report.py; docs/performance.md, "Ninth round"). The report services are therefore
created without registering them with the node (the executor never sees them; the ROS graph
still lists them under the node, since rcl creates them on it) and one thread waits on them
alone: take a request, call the service's callback, send its answer, exactly as the executor
would, but without the rebuild and the task; after each turn it publishes the events of
what it answered. The callbacks are the node's own (``guard_service``: they never raise),
so they run unchanged; reads, clears, the events of other changes and the bridges stay with
the executor.

This uses two entry points of rclpy's implementation module (``Service`` and ``WaitSet``,
which rclpy's own executor uses): the ROS 2 wheels are pinned (requirements-ros.txt), and
tests/ros exercise every report through this loop.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import Any, cast

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.service import Service
from rclpy.type_support import check_is_valid_srv_type

from faultledger.ros.guard import Logger, guard_callback

WAIT_TIMEOUT_NS = 500_000_000
"""The loop looks at its stop flag at least this often (``close`` also wakes it at once)."""
FAILURE_PAUSE_S = 0.01
"""After a turn that raised (logged by ``guard_callback``), before the next."""


def detached_service(node: Node, srv_type: Any, name: str,
                     callback: Callable[[Any, Any], Any], qos: QoSProfile) -> Service:
    """A service of ``node`` that no executor serves (``ReportLoop`` does)."""
    check_is_valid_srv_type(srv_type)  # loads the type support, as Node.create_service does
    with node.handle:
        impl = _rclpy.Service(node.handle, srv_type, name, qos.get_c_qos_profile())
    return Service(impl, srv_type, name, callback, MutuallyExclusiveCallbackGroup(), qos)


class ReportLoop:
    """One thread answering ``services`` one request at a time, in arrival order per service.

    A callback may take the requests queued behind its own (service_queue.py) and answer them
    itself; the loop sends the answer the callback returns.
    """

    def __init__(self, node: Node, services: list[Service], logger: Logger,
                 after: Callable[[], None]) -> None:
        """``after()``: called once a turn's answers are sent (the node publishes the events
        of the reports just answered)."""
        self._services = services
        self._after = after
        self._context = node.context
        self._context_handle = cast(Any, node.context.handle)  # typed Optional by rclpy
        self._stop = threading.Event()
        self._wake = GuardCondition(None, None, context=node.context)
        with self._context_handle:
            self._wait_set = _rclpy.WaitSet(0, 1, 0, 0, len(services), 0,
                                            self._context_handle)
        self._turn = guard_callback(self._serve_ready, logger, "report loop")
        self._failing = False
        self._thread = threading.Thread(target=self._run, name="fault_manager_reports",
                                        daemon=True)
        self._thread.start()

    @property
    def thread_id(self) -> int | None:
        return self._thread.ident

    def _run(self) -> None:
        while not self._stop.is_set() and self._context.ok():
            self._turn()
            if self._failing:  # logged (rate-limited); do not spin on a lasting failure
                self._stop.wait(FAILURE_PAUSE_S)

    def _serve_ready(self) -> None:
        """Wait for requests (or ``close``), then answer one per ready service."""
        self._failing = True
        with contextlib.ExitStack() as held:  # no handle is destroyed while waited on
            held.enter_context(self._context_handle)
            for service in self._services:
                held.enter_context(service.handle)
            held.enter_context(self._wake.handle)
            wait_set = self._wait_set
            wait_set.clear_entities()
            for service in self._services:
                wait_set.add_service(service.handle)
            wait_set.add_guard_condition(self._wake.handle)
            wait_set.wait(WAIT_TIMEOUT_NS)
            ready = wait_set.get_ready_entities("service")
        if not self._stop.is_set():
            try:
                for service in self._services:
                    if service.handle.pointer in ready:
                        self._answer_one(service)
            finally:  # what was committed is published even if an answer failed
                self._after()
        self._failing = False

    @staticmethod
    def _answer_one(service: Service) -> None:
        request_type: Any = service.srv_type
        with service.handle:
            request, header = service.handle.service_take_request(request_type.Request)
        if header is None:  # taken meanwhile (e.g. by the callback before: a burst)
            return
        response = service.callback(request, request_type.Response())
        service.send_response(response, header)

    def close(self) -> None:
        """Stop the thread (a callback running finishes first) and destroy the services."""
        self._stop.set()
        with contextlib.suppress(Exception):
            self._wake.trigger()
        self._thread.join()
        for service in self._services:
            with contextlib.suppress(Exception):
                service.destroy()
        with contextlib.suppress(Exception):
            self._wake.destroy()
