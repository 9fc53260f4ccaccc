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

Goal outcomes (``report_goal_outcome``, used by the action-status bridge) travel the same way
on a queue of their own to ``report_goal_outcome``, which stores one outcome per (action,
goal_id): their retries are exactly-once too. A plain medkit manager has no such service;
outcomes then wait in their queue (the oldest dropped when it is full).
"""

from __future__ import annotations

import threading
import time
import uuid
from collections import deque
from typing import Any, NamedTuple, TypeVar

from builtin_interfaces.msg import Time
from faultledger_msgs.srv import ReportFaultOnce, ReportGoalOutcome
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from ros2_medkit_msgs.srv import ReportFault

from faultledger.ros.guard import clip, guard_callback
from faultledger.ros.local_filter import PARAMETER_PREFIX, FilterConfig, LocalFilter

MIN_QOS_DEPTH = 1000
"""The client's request/response queue depth: the default 10 silently drops bursts."""
GOAL_STATUSES = ("SUCCEEDED", "ABORTED", "CANCELED")
NS_PER_SECOND = 1_000_000_000
MAX_STAMP_NS = (2**31 - 1) * NS_PER_SECOND + NS_PER_SECOND - 1
"""The latest time a builtin_interfaces/Time carries (int32 sec)."""


class _Report(NamedTuple):
    """One report waiting for the manager's answer; event_id stays the same across retries."""

    fault_code: str
    event_type: int
    severity: int
    description: str
    event_id: str
    source_id: str

    @property
    def what(self) -> str:
        return f"'{clip(self.fault_code)}'"


class _Outcome(NamedTuple):
    """One goal outcome waiting for the manager's answer; (action, goal_id) is its key."""

    action: str
    goal_id: str
    status: str
    server_node: str
    stamp_ns: int

    @property
    def what(self) -> str:
        return f"goal outcome of '{clip(self.action)}' goal '{clip(self.goal_id)}'"


_Item = TypeVar("_Item", _Report, _Outcome)


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
        self._outcomes: deque[_Outcome] = deque()  # oldest first
        self._outcomes_in_flight: list[tuple[Future, _Outcome, float]] = []
        self._dropped = 0
        self._dropped_outcomes = 0
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(queue_size, MIN_QOS_DEPTH),
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
        group = MutuallyExclusiveCallbackGroup()  # not starved by the user's own callbacks
        self._node = node
        self._manager = manager
        self._qos = qos
        self._group = group
        self._goals: Any = None  # the report_goal_outcome client, created at the first outcome
        self._once = node.create_client(ReportFaultOnce, f"{manager}/report_fault_once",
                                        qos_profile=qos, callback_group=group)
        self._plain = node.create_client(ReportFault, f"{manager}/report_fault",
                                         qos_profile=qos, callback_group=group)
        self._timer = node.create_timer(
            flush_period_sec, guard_callback(self._on_timer, self._log, "FaultReporter timer"),
            callback_group=group)

    def report(self, fault_code: str, severity: int, description: str = "", *,
               source_id: str | None = None) -> bool:
        """Report a FAILED event; True if sent or queued, False if filtered out or unusable.

        ``source_id`` overrides the reporter's for this report: a bridge reports on behalf
        of the nodes and devices it watches.
        """
        if not self._usable(fault_code, description=description, source_id=source_id):
            return False
        if not isinstance(severity, int) or not 0 <= severity <= 255:
            # would not fit the uint8 field; the manager takes 0..3
            self._log.warning(f"FaultReporter: severity {clip(severity)} of "
                              f"'{clip(fault_code)}'; ignored")
            return False
        with self._lock:
            if not self._filter.should_forward(fault_code, severity):
                return False
            self._enqueue(_Report(fault_code, ReportFault.Request.EVENT_FAILED, severity,
                                  description, str(uuid.uuid4()), source_id or self._source_id))
        return True

    def report_passed(self, fault_code: str, *, source_id: str | None = None) -> bool:
        """Report a PASSED event (the check succeeded); True if sent or queued."""
        if not self._usable(fault_code, source_id=source_id):
            return False
        with self._lock:
            if not self._filter.should_forward_passed(fault_code):
                return False
            self._enqueue(_Report(fault_code, ReportFault.Request.EVENT_PASSED, 0, "",
                                  str(uuid.uuid4()), source_id or self._source_id))
        return True

    def report_goal_outcome(self, action: str, goal_id: str, status: str, *,
                            server_node: str = "", stamp_ns: int = 0) -> bool:
        """Record the terminal status (SUCCEEDED, ABORTED, CANCELED) of one action goal;
        True if sent or queued, False if unusable (logged).

        ``goal_id`` is the goal's UUID text, ``server_node`` the action server's node (empty:
        unknown), ``stamp_ns`` when the goal ended (ns since the epoch; 0: the manager's
        receive time). No local filter; retried like reports, and stored once per (action,
        goal_id) however often it is sent.
        """
        if not self._sendable_strings((("action", action), ("goal_id", goal_id),
                                       ("status", status), ("server_node", server_node)),
                                      "goal outcome"):
            return False
        if not action or not goal_id or status not in GOAL_STATUSES:
            self._log.warning(f"FaultReporter: goal outcome needs an action, a goal id and a "
                              f"status of {', '.join(GOAL_STATUSES)}, got action "
                              f"'{clip(action)}', goal '{clip(goal_id)}', status "
                              f"'{clip(status)}'; ignored")
            return False
        if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, int) or not (
                0 <= stamp_ns <= MAX_STAMP_NS):
            self._log.warning(f"FaultReporter: goal outcome stamp_ns {clip(stamp_ns)} of "
                              f"'{clip(action)}' goal '{clip(goal_id)}' is not a time a ROS "
                              f"Time can carry; ignored")
            return False
        with self._lock:
            if self._goals is None:
                self._goals = self._node.create_client(
                    ReportGoalOutcome, f"{self._manager}/report_goal_outcome",
                    qos_profile=self._qos, callback_group=self._group)
            if len(self._outcomes) >= self._queue_size:
                self._drop_oldest_outcome()
            self._outcomes.append(_Outcome(action, goal_id, status, server_node, stamp_ns))
            self._send_outcomes()
        return True

    @property
    def pending(self) -> int:
        """Reports and goal outcomes not yet answered by the manager (queued plus in
        flight)."""
        with self._lock:
            return (len(self._queue) + len(self._in_flight) + len(self._outcomes)
                    + len(self._outcomes_in_flight))

    def destroy(self) -> None:
        """Stop retrying and release the timer and clients; unsent reports are lost."""
        self._node.destroy_timer(self._timer)
        self._node.destroy_client(self._once)
        self._node.destroy_client(self._plain)
        if self._goals is not None:
            self._node.destroy_client(self._goals)

    def _usable(self, fault_code: str, *, description: str = "",
                source_id: str | None = None) -> bool:
        """A report that can travel as it is: a non-empty code, and strings without NUL (a ROS
        string ends at the first NUL: the manager would receive ``AB`` for ``AB\\x00CD``,
        a different fault, and accept it; docs/ros.md)."""
        if not isinstance(fault_code, str) or not fault_code:
            self._log.warning(f"FaultReporter: empty or non-string fault_code "
                              f"{clip(fault_code)}; ignored")
            return False
        return self._sendable_strings(
            (("fault_code", fault_code), ("description", description),
             ("source_id", self._source_id if source_id is None else source_id)),
            f"report of '{clip(fault_code)}'")

    def _sendable_strings(self, fields: tuple[tuple[str, object], ...], what: str) -> bool:
        """Strings a ROS message carries faithfully: of type str and without NUL (a ROS
        string ends at the first NUL); else one warning naming the field, and False."""
        for name, value in fields:
            if not isinstance(value, str):
                self._log.warning(f"FaultReporter: {what}: {name} {clip(value)} is not a "
                                  f"string ({type(value).__name__}); ignored")
                return False
            if "\x00" in value:
                self._log.warning(f"FaultReporter: {what}: {name} '{clip(value)}' contains a "
                                  f"NUL character (\\x00), which a ROS string cannot carry; "
                                  f"ignored")
                return False
        return True

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
                          f"report '{clip(old.fault_code)}' ({self._dropped} dropped so far)",
                          throttle_duration_sec=5.0)

    def _drop_oldest_outcome(self) -> None:
        old = self._outcomes.popleft()
        self._dropped_outcomes += 1
        self._log.warning(f"FaultReporter: goal outcome queue full ({self._queue_size}); "
                          f"dropped the oldest, {old.what} ({self._dropped_outcomes} dropped "
                          f"so far)", throttle_duration_sec=5.0)

    def _send_outcomes(self) -> None:
        """Send the queued goal outcomes when the manager's service is ready (lock held)."""
        client = self._goals
        if not self._outcomes or client is None or not client.service_is_ready():
            return
        deadline = time.monotonic() + self._timeout
        while self._outcomes:
            outcome = self._outcomes.popleft()
            seconds, nanoseconds = divmod(outcome.stamp_ns, NS_PER_SECOND)
            request = ReportGoalOutcome.Request(
                action=outcome.action, goal_id=outcome.goal_id, status=outcome.status,
                server_node=outcome.server_node, stamp=Time(sec=seconds, nanosec=nanoseconds))
            self._outcomes_in_flight.append((client.call_async(request), outcome, deadline))

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
            self._in_flight, lost = self._retire(self._in_flight, now,
                                                 (self._once, self._plain))
            if lost:
                self._log.warning(f"FaultReporter: {len(lost)} report(s) unanswered after "
                                  f"{self._timeout} s; re-sending when the manager is ready")
                self._queue.extendleft(reversed(lost))
                while len(self._queue) > self._queue_size:
                    self._drop_oldest()
            self._send_queued()
            self._outcomes_in_flight, lost_outcomes = self._retire(
                self._outcomes_in_flight, now, (self._goals,))
            if lost_outcomes:
                self._log.warning(f"FaultReporter: {len(lost_outcomes)} goal outcome(s) "
                                  f"unanswered after {self._timeout} s; re-sending when the "
                                  f"manager is ready")
                self._outcomes.extendleft(reversed(lost_outcomes))
                while len(self._outcomes) > self._queue_size:
                    self._drop_oldest_outcome()
            self._send_outcomes()

    def _retire(self, in_flight: list[tuple[Future, _Item, float]], now: float,
                clients: tuple[Any, ...]) -> tuple[list[tuple[Future, _Item, float]], list[_Item]]:
        """(still waiting, unanswered past their deadline) of ``in_flight``; answers are
        retired, failures and rejections logged (lock held)."""
        waiting, lost = [], []
        for future, item, deadline in in_flight:
            if future.done():
                error = future.exception()
                response = None if error is not None else future.result()
                if error is not None:
                    self._log.warning(f"FaultReporter: sending {item.what} failed: "
                                      f"{clip(repr(error))}")
                elif response is not None and not response.accepted:
                    reason = getattr(response, "message", "") or "no reason given"
                    self._log.warning(f"FaultReporter: manager rejected {item.what}: "
                                      f"{clip(reason)}")
            elif now >= deadline:
                for client in clients:  # a late answer is ignored
                    if client is not None:
                        client.remove_pending_request(future)
                lost.append(item)
            else:
                waiting.append((future, item, deadline))
        return waiting, lost
