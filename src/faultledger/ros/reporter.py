"""FaultReporter: what a node calls to report faults, filtered locally and never lost to a restart.

Like ros2_medkit's reporter it filters locally and never blocks the caller (``call_async``).
Unlike medkit, which drops reports while the manager is down, it keeps a bounded queue: a
report made before the manager is up, or sent to a manager that died before answering, is
(re)sent once the service is ready.

Retries must not double count (one e-stop press is one FAILED). Each report gets a UUID that
every retry reuses, sent through faultledger's ``report_fault_once`` service, which stores an
event_id once: delivery is exactly-once. Against a plain medkit manager (no such service) the
reporter falls back to ``report_fault`` and delivery becomes at-least-once: a manager that
answers later than ``response_timeout_sec`` may see a report twice.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections import deque
from typing import NamedTuple

from faultledger_msgs.srv import ReportFaultOnce
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from ros2_medkit_msgs.srv import ReportFault

from faultledger.ros.local_filter import PARAMETER_PREFIX, FilterConfig, LocalFilter

MIN_QOS_DEPTH = 1000
"""The client's request/response queue depth: the default 10 silently drops bursts."""


class _Report(NamedTuple):
    """One report waiting for the manager's answer; event_id stays the same across retries."""

    fault_code: str
    event_type: int
    severity: int
    description: str
    event_id: str
    source_id: str


class FaultReporter:
    """Reports FAILED/PASSED events for one source to the fault manager's ReportFault service."""

    def __init__(self, node: Node, source_id: str, *,
                 manager: str = "/fault_manager", queue_size: int = 1000,
                 response_timeout_sec: float = 5.0, flush_period_sec: float = 0.25,
                 local_filtering: bool = True) -> None:
        """``local_filtering=False`` forwards every report and ignores the filter parameters:
        for bridges, whose reports are edge-triggered already."""
        self._log = node.get_logger()
        if not source_id:
            self._log.warning("FaultReporter: empty source_id; the manager will reject reports")
        if queue_size < 1:
            self._log.warning(f"FaultReporter: queue_size={queue_size} is below 1; using 1")
            queue_size = 1
        self._source_id = source_id
        self._queue_size = queue_size
        self._timeout = response_timeout_sec
        self._filter = LocalFilter(self._read_parameters(node) if local_filtering
                                   else FilterConfig(enabled=False))
        self._lock = threading.Lock()  # report() may run on any thread, the timer on the executor
        self._queue: deque[_Report] = deque()  # oldest first
        self._in_flight: list[tuple[Future, _Report, float]] = []  # (future, report, deadline)
        self._dropped = 0
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(queue_size, MIN_QOS_DEPTH),
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        group = MutuallyExclusiveCallbackGroup()  # not starved by the user's own callbacks
        self._node = node
        self._once = node.create_client(ReportFaultOnce, f"{manager}/report_fault_once",
                                        qos_profile=qos, callback_group=group)
        self._plain = node.create_client(ReportFault, f"{manager}/report_fault",
                                         qos_profile=qos, callback_group=group)
        self._timer = node.create_timer(flush_period_sec, self._on_timer, callback_group=group)

    def report(self, fault_code: str, severity: int, description: str = "", *,
               source_id: str | None = None) -> bool:
        """Report a FAILED event; True if sent or queued, False if filtered out or unusable.

        ``source_id`` overrides the reporter's for this report: a bridge reports on behalf
        of the nodes and devices it watches.
        """
        if not self._usable(fault_code):
            return False
        if not 0 <= severity <= 255:  # would not fit the uint8 field; the manager takes 0..3
            self._log.warning(f"FaultReporter: severity {severity} of '{fault_code}'; ignored")
            return False
        with self._lock:
            if not self._filter.should_forward(fault_code, severity):
                return False
            self._enqueue(_Report(fault_code, ReportFault.Request.EVENT_FAILED, severity,
                                  description, str(uuid.uuid4()), source_id or self._source_id))
        return True

    def report_passed(self, fault_code: str, *, source_id: str | None = None) -> bool:
        """Report a PASSED event (the check succeeded); True if sent or queued."""
        if not self._usable(fault_code):
            return False
        with self._lock:
            if not self._filter.should_forward_passed(fault_code):
                return False
            self._enqueue(_Report(fault_code, ReportFault.Request.EVENT_PASSED, 0, "",
                                  str(uuid.uuid4()), source_id or self._source_id))
        return True

    @property
    def pending(self) -> int:
        """Reports not yet answered by the manager (queued plus in flight)."""
        with self._lock:
            return len(self._queue) + len(self._in_flight)

    def destroy(self) -> None:
        """Stop retrying and release the timer and client; unsent reports are lost."""
        self._node.destroy_timer(self._timer)
        self._node.destroy_client(self._once)
        self._node.destroy_client(self._plain)

    def _usable(self, fault_code: str) -> bool:
        if not fault_code:
            self._log.warning("FaultReporter: empty fault_code; ignored")
        return bool(fault_code)

    def _read_parameters(self, node: Node) -> FilterConfig:
        # Dynamically typed, so `default_window_sec: 10` (an int in YAML) is normalised with a
        # warning instead of failing the declaration; a node with several reporters shares them.
        raw = []
        for name, default in (("enabled", True), ("default_threshold", 3),
                              ("default_window_sec", 10.0), ("bypass_severity", 2)):
            full = PARAMETER_PREFIX + name
            if not node.has_parameter(full):
                node.declare_parameter(full, default, ParameterDescriptor(dynamic_typing=True))
            raw.append(node.get_parameter(full).value)
        config, problems = FilterConfig.from_raw(*raw)
        for problem in problems:
            self._log.warning(f"FaultReporter: {problem}")
        return config

    def _enqueue(self, request: _Report) -> None:
        """Append (lock held), dropping the oldest when full; send what the manager can take."""
        if len(self._queue) >= self._queue_size:
            self._drop_oldest()
        self._queue.append(request)
        self._send_queued()

    def _drop_oldest(self) -> None:
        old = self._queue.popleft()
        self._dropped += 1
        self._log.warning(f"FaultReporter: queue full ({self._queue_size}); dropped the oldest "
                          f"report '{old.fault_code}' ({self._dropped} dropped so far)",
                          throttle_duration_sec=5.0)

    def _send_queued(self) -> None:
        # Lock held, so requests leave in the order they were made (FAILED before PASSED matters).
        if not self._queue:
            return
        client, kind = self._once, ReportFaultOnce.Request
        if not client.service_is_ready():
            client, kind = self._plain, ReportFault.Request  # a medkit manager: at-least-once
            if not client.service_is_ready():
                return
        deadline = time.monotonic() + self._timeout
        while self._queue:
            report = self._queue.popleft()
            request = kind(fault_code=report.fault_code, event_type=report.event_type,
                           severity=report.severity, description=report.description,
                           source_id=report.source_id)
            if kind is ReportFaultOnce.Request:
                request.event_id = report.event_id
            self._in_flight.append((client.call_async(request), report, deadline))

    def _on_timer(self) -> None:
        """Retire answered requests, re-queue unanswered ones, send if the manager is up."""
        with self._lock:
            now = time.monotonic()
            waiting, lost = [], []
            for future, report, deadline in self._in_flight:
                if future.done():
                    response = future.result()
                    if response is not None and not response.accepted:
                        reason = getattr(response, "message", "") or "no reason given"
                        self._log.warning(f"FaultReporter: manager rejected "
                                          f"'{report.fault_code}': {reason}")
                elif now >= deadline:
                    for client in (self._once, self._plain):  # a late answer is ignored
                        client.remove_pending_request(future)
                    lost.append(report)
                else:
                    waiting.append((future, report, deadline))
            self._in_flight = waiting
            if lost:
                self._log.warning(f"FaultReporter: {len(lost)} report(s) unanswered after "
                                  f"{self._timeout} s; re-sending when the manager is ready")
                self._queue.extendleft(reversed(lost))
                while len(self._queue) > self._queue_size:
                    self._drop_oldest()
            self._send_queued()
