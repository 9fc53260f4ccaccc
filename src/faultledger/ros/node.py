"""The `fault_manager` node: ROS services and the events topic over one FaultLedger.

Callbacks only translate: request → FaultLedger call → response. A report (or goal outcome)
callback also takes the requests queued behind its own (service_queue.py), so a burst from many
clients shares group commits although the executor runs one callback at a time.

Reads (list, get, history, statistics) run on a small thread pool (``ReadPool``): their
callbacks are coroutines that await the pool's answer, so the executor thread keeps serving
reports while a long statistics query computes. Every callback goes through ``guard.py``: an
exception becomes a failed answer and one log line, never the end of the process.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections import deque
from collections.abc import Callable, Coroutine
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from faultledger_msgs.srv import (
    AcknowledgeFault,
    GetHistory,
    GetStatistics,
    ReportFaultOnce,
    ReportGoalOutcome,
)
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.service import Service
from rclpy.task import Future
from ros2_medkit_msgs.msg import FaultEvent
from ros2_medkit_msgs.srv import (
    ClearFault,
    GetFault,
    ListFaults,
    ListFaultsForEntity,
    ReportFault,
)

from faultledger.domain.notifications import Notification
from faultledger.domain.policy import Policy
from faultledger.domain.types import MEDKIT_NOTIFICATIONS
from faultledger.errors import InvalidInputError
from faultledger.ros import convert
from faultledger.ros.guard import (
    MESSAGE_LIMIT,
    clip,
    error_text,
    fail,
    guard_callback,
    guard_service,
    log_failure,
)
from faultledger.ros.report_loop import ReportLoop, detached_service
from faultledger.ros.service_queue import take_queued
from faultledger.service.ledger import FaultLedger
from faultledger.service.requests import GoalOutcomeRequest, ReportRequest
from faultledger.service.results import ReportResult

log = logging.getLogger(__name__)

NODE_NAME = "fault_manager"
SERVICE_QUEUE_DEPTH = 10_000
"""Requests a service keeps queued: above any burst we test (4 clients x 500), so a fault
storm is answered instead of silently dropped (the default depth is 10)."""
HISTORY_LIMIT = 10_000
"""Most records one get_history answer carries; page with since/until."""
READ_THREADS = 2
"""Threads answering reads: a long statistics query leaves one for the others."""
MAX_READS_IN_FLIGHT = 32
"""Reads handed to the pool and not yet answered. Beyond it a read is answered on the executor
thread (as every read was before the pool): a flood of reads slows the flood down instead of
piling up coroutines that the executor polls on every turn."""

SERVICE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=SERVICE_QUEUE_DEPTH,
                         reliability=ReliabilityPolicy.RELIABLE)
EVENTS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)


def declare_policy(node: Node, policy: Policy) -> Policy:
    """medkit's parameter names override the config file's global policy values."""
    node.declare_parameter("confirmation_threshold", policy.confirmation_threshold)
    node.declare_parameter("healing_enabled", policy.healing_enabled)
    node.declare_parameter("healing_threshold", policy.healing_threshold)
    node.declare_parameter("auto_confirm_after_sec", float(policy.auto_confirm_after_sec))
    value = {name: node.get_parameter(name).value for name in (
        "confirmation_threshold", "healing_enabled", "healing_threshold",
        "auto_confirm_after_sec")}
    return Policy.model_validate({**policy.model_dump(), **value})


ServiceCallback = Callable[[Any, Any], Any]


class ReadPool:
    """Runs read callbacks on ``READ_THREADS`` threads; the executor awaits their answers.

    ``offload(callback)`` is an ``async`` service callback: rclpy runs it as a task, which
    yields while the pool works and sends the response when the coroutine returns. The
    worker triggers a guard condition when done, so the executor wakes at once instead of
    at its next timeout. ``callback`` must not raise (``guard_service``).
    """

    def __init__(self, node: Node, group: ReentrantCallbackGroup) -> None:
        self._pool = ThreadPoolExecutor(READ_THREADS, thread_name_prefix="fault_manager_read")
        self._lock = threading.Lock()
        self._in_flight = 0
        self._closed = False
        self._wake = node.create_guard_condition(lambda: None, callback_group=group)

    @property
    def in_flight(self) -> int:
        with self._lock:
            return self._in_flight

    def offload(self, callback: ServiceCallback
                ) -> Callable[[Any, Any], Coroutine[Any, Any, Any]]:
        async def offloaded(request: Any, response: Any) -> Any:
            answer = self._submit(callback, request, response)
            if answer is None:  # pool full or closed: answer here, as before the pool
                return callback(request, response)
            try:
                return await answer
            finally:
                with self._lock:
                    self._in_flight -= 1

        return offloaded

    def _submit(self, callback: ServiceCallback, request: Any, response: Any
                ) -> Future | None:
        with self._lock:
            if self._closed or self._in_flight >= MAX_READS_IN_FLIGHT:
                return None
            self._in_flight += 1
        answer = Future()

        def work() -> None:
            result: Any = None
            try:
                result = callback(request, response)
            finally:
                answer.set_result(result if result is not None
                                  else fail(type(response)(), "internal error: no answer"))
                with contextlib.suppress(Exception):  # destroyed at shutdown; answer is set
                    self._wake.trigger()

        try:
            self._pool.submit(work)
        except RuntimeError:  # shut down meanwhile
            with self._lock:
                self._in_flight -= 1
            return None
        return answer

    def close(self) -> None:
        """No new work; work not started yet is dropped (its callers are answered by nobody:
        called once the executor stopped)."""
        with self._lock:
            self._closed = True
        self._pool.shutdown(wait=False, cancel_futures=True)


class FaultManagerNode:
    """Services and publisher of `/fault_manager`, bound to an open ledger."""

    def __init__(self, node: Node, ledger: FaultLedger, *, read_only: bool = False,
                 leader: str = "/" + NODE_NAME) -> None:
        """``read_only``: a follower (docs/ros.md "A second fault manager"): the write
        services answer a refusal naming ``leader``, nothing is published, nothing written."""
        self.node = node
        self.ledger = ledger
        self.log = node.get_logger()
        self.read_only = read_only
        self.leader = leader
        self.events = node.create_publisher(FaultEvent, "~/events", EVENTS_QOS)

        def write(callback: ServiceCallback, name: str) -> ServiceCallback:
            return guard_service(self._refuse_write(name) if read_only else callback,
                                 self.log, name)

        def report(kind: Any, name: str, callback: ServiceCallback) -> Service:
            """A report service: served by the report loop (report_loop.py); a follower's,
            which only refuses, by the executor."""
            if read_only:
                return node.create_service(kind, f"~/{name}", write(callback, name),
                                           qos_profile=SERVICE_QOS)
            return detached_service(node, kind, f"~/{name}", write(callback, name),
                                    SERVICE_QOS)

        self.report_service = report(ReportFault, "report_fault", self.report_fault)
        self.report_once_service = report(ReportFaultOnce, "report_fault_once",
                                          self.report_fault_once)
        self.goal_service = report(ReportGoalOutcome, "report_goal_outcome",
                                   self.report_goal_outcome)
        reports = [self.report_service, self.report_once_service, self.goal_service]
        self.clear_service = node.create_service(
            ClearFault, "~/clear_fault", write(self.clear_fault, "clear_fault"),
            qos_profile=SERVICE_QOS)
        self.acknowledge_service = node.create_service(
            AcknowledgeFault, "~/acknowledge_fault",
            write(self.acknowledge_fault, "acknowledge_fault"), qos_profile=SERVICE_QOS)
        # Reads: a reentrant group, so a read awaiting the pool holds up neither the reports
        # (the node's default, mutually exclusive group) nor other reads.
        self.read_group = ReentrantCallbackGroup()
        self.reads = ReadPool(node, self.read_group)
        reads: list[tuple[Any, str, ServiceCallback]] = [
            (ListFaults, "list_faults", self.list_faults),
            (GetFault, "get_fault", self.get_fault),
            (ListFaultsForEntity, "list_faults_for_entity", self.list_faults_for_entity),
            (GetHistory, "get_history", self.get_history),
            (GetStatistics, "get_statistics", self.get_statistics),
        ]
        self.services = [*(reports if read_only else []),
                         self.clear_service, self.acknowledge_service, *(
            node.create_service(kind, f"~/{name}",
                                self.reads.offload(guard_service(callback, self.log, name)),
                                qos_profile=SERVICE_QOS, callback_group=self.read_group)
            for kind, name, callback in reads)]
        self._unpublished: deque[Notification] = deque()
        self._publishing = threading.Lock()
        self._event = FaultEvent()
        """The message every event is written into before it is published (under
        ``_publishing``; ``convert.event_msg``)."""
        self.report_loop: ReportLoop | None = None
        self._publish_guarded = guard_callback(self._publish_queued, self.log,
                                               "events publisher")
        self._publish_now = node.create_guard_condition(self._publish_guarded)
        self.subscription = ledger.subscribe(self.publish)
        if not read_only:
            self.report_loop = ReportLoop(node, reports, self.log, self._publish_guarded)

    def _refuse_write(self, name: str) -> ServiceCallback:
        """A follower's answer to a write: refused, with where to send it instead."""
        text = (f"{self.node.get_fully_qualified_name()} is a read-only follower: {name} "
                f"refused; send it to {self.leader}/{name}")

        def refuse(_request: Any, response: Any) -> Any:
            self.log.warning(text)
            return fail(response, text)

        return refuse

    def publish(self, notification: Notification) -> None:
        """Called by the ledger after the change is durable, in log order (on the thread
        that committed it). Only medkit's event types: a drop-in peer's subscribers know no
        others (acknowledgements and shelvings are on the HTTP stream).

        The message is queued and published after the answer to the report that caused
        it, so a reporter waits for its commit and not also for the event (a tenth of a
        report's round trip; docs/performance.md): by the report loop once it has sent its
        answers, or, for a change committed on another thread (a clear, a timer), by the
        executor (a guard condition). The queue keeps log order; ``close`` publishes what
        is left."""
        if notification.event_type in MEDKIT_NOTIFICATIONS:
            self._unpublished.append(notification)
            loop = self.report_loop
            if loop is None or loop.thread_id != threading.get_ident():
                self._publish_now.trigger()
            # else the report loop publishes once it has sent its answers (``after``)

    def _publish_queued(self) -> None:
        with self._publishing:  # two threads publish (executor, report loop): one at a time
            while self._unpublished:
                self.events.publish(convert.event_msg(self._unpublished.popleft(),
                                                      self._event))

    def report_fault(self, request: Any, response: Any) -> Any:
        return self._report_burst(self.report_service, request, response, idempotent=False)

    def report_fault_once(self, request: Any, response: Any) -> Any:
        return self._report_burst(self.report_once_service, request, response, idempotent=True)

    def _report_burst(self, service: Service, request: Any, response: Any,
                      idempotent: bool) -> Any:
        """Make this report and every one queued behind it durable in shared commits.

        Every taken request is answered, whatever happens: an unexpected exception answers
        them all ``accepted=false`` (one log line for the burst)."""
        queued = take_queued(service)
        requests = [request, *(r for r, _ in queued)]
        name = "report_fault_once" if idempotent else "report_fault"
        try:
            results = self.ledger.report_many([
                ReportRequest(r.fault_code, r.event_type, r.severity, r.description,
                              r.source_id, event_id=r.event_id if idempotent else None)
                for r in requests])
        except Exception as error:
            log_failure(self.log, name, error, f" ({len(requests)} report(s) not accepted)")
            results = [ReportResult(False, error_text(error))] * len(requests)
        else:
            self._log_rejected(requests, results, lambda r: (
                f"report of '{clip(r.fault_code)}' from '{clip(r.source_id)}'"))
        self._answer_queued(service, queued, results[1:], name)
        return self._answer(response, results[0])

    def report_goal_outcome(self, request: Any, response: Any) -> Any:
        """Record this goal outcome and every one queued behind it in shared commits, like
        ``_report_burst``; a request the ledger cannot take (a bad stamp, an unknown status)
        is answered ``accepted=false`` on its own."""
        service = self.goal_service
        queued = take_queued(service)
        requests = [request, *(r for r, _ in queued)]
        name = "report_goal_outcome"
        results: list[ReportResult | None] = []
        valid: list[GoalOutcomeRequest] = []
        for r in requests:
            try:
                valid.append(convert.goal_outcome_request(r))
                results.append(None)
            except InvalidInputError as error:
                results.append(ReportResult(False, error_text(error)))
        try:
            recorded = iter(self.ledger.record_goal_outcomes(valid))
        except Exception as error:
            log_failure(self.log, name, error, f" ({len(valid)} goal outcome(s) not accepted)")
            recorded = iter([ReportResult(False, error_text(error))] * len(valid))
        answers = [result if result is not None else next(recorded) for result in results]
        self._log_rejected(requests, answers, lambda r: (
            f"goal outcome of '{clip(r.action)}' goal '{clip(r.goal_id)}' from "
            f"'{clip(r.server_node)}'"))
        self._answer_queued(service, queued, answers[1:], name)
        return self._answer(response, answers[0])

    def _log_rejected(self, requests: list[Any], results: list[ReportResult],
                      describe: Callable[[Any], str]) -> None:
        """One warning per request of a burst that was not accepted: ``<describe(request)>
        rejected: <why>``."""
        for r, result in zip(requests, results, strict=True):
            if not result.accepted:
                self.log.warning(
                    f"{describe(r)} rejected: {clip(result.message, MESSAGE_LIMIT)}")

    def _answer_queued(self, service: Service, queued: list[tuple[Any, Any]],
                       results: list[ReportResult], name: str) -> None:
        """Answer the requests a callback took from the queue (``take_queued``)."""
        kind: Any = service.srv_type
        for (_, header), result in zip(queued, results, strict=True):
            try:
                service.send_response(self._answer(kind.Response(), result), header)
            except Exception as error:  # one lost answer must not cost the others theirs
                log_failure(self.log, f"{name} (answering a queued request)", error)

    @staticmethod
    def _answer(response: Any, result: ReportResult) -> Any:
        response.accepted = result.accepted
        if hasattr(response, "duplicate"):  # ReportFaultOnce, ReportGoalOutcome
            response.duplicate = result.duplicate
            response.message = "" if result.accepted else clip(result.message, MESSAGE_LIMIT)
        return response

    def list_faults(self, request: Any, response: Any) -> Any:
        severity = request.severity if request.filter_by_severity else None
        response.faults = [convert.fault_msg(f)
                           for f in self.ledger.list_faults(request.statuses, severity)]
        response.muted_count = 0
        response.cluster_count = 0
        return response

    def get_fault(self, request: Any, response: Any) -> Any:
        lookup = self.ledger.lookup_fault(request.fault_code)
        response.success = lookup.success
        response.error_message = lookup.message
        if lookup.fault is not None:
            response.fault = convert.fault_msg(lookup.fault)
            records = response.environment_data.extended_data_records
            records.first_occurrence_ns = lookup.fault.first_occurred_ns
            records.last_occurrence_ns = lookup.fault.last_occurred_ns
        return response

    def clear_fault(self, request: Any, response: Any) -> Any:
        result = self.ledger.clear(request.fault_code, actor="ros:clear_fault")
        response.success = result.success
        response.message = result.message
        response.auto_cleared_codes = []
        return response

    def acknowledge_fault(self, request: Any, response: Any) -> Any:
        result = self.ledger.acknowledge(request.fault_code,
                                         actor=request.actor or "ros:acknowledge_fault",
                                         note=request.note)
        response.success = result.success
        response.recorded = result.seq is not None
        response.episode = 0 if result.fault is None or not result.success else (
            result.fault.episode)
        response.message = result.message
        return response

    def list_faults_for_entity(self, request: Any, response: Any) -> Any:
        lookup = self.ledger.lookup_entity(request.entity_id)
        response.success = lookup.success
        response.error_message = lookup.message
        response.faults = [convert.fault_msg(f) for f in lookup.faults]
        return response

    def get_history(self, request: Any, response: Any) -> Any:
        """Refused input raises InvalidInputError: ``guard_service`` answers success=false."""
        since = convert.request_ns(request.since, "since")
        until = convert.request_ns(request.until, "until")
        limit = min(request.limit or HISTORY_LIMIT, HISTORY_LIMIT)
        records = self.ledger.history(
            code=request.fault_code or None, source=request.source_id or None,
            since=since or None, until=until or None,
            kinds=list(request.kinds), limit=limit)
        response.success = True
        response.records = [convert.record_msg(r) for r in records]
        return response

    def get_statistics(self, request: Any, response: Any) -> Any:
        """``FaultLedger.stats`` in the ledger's calendar; refused input (InvalidInputError) →
        success=false with its message (``guard_service``)."""
        rows = self.ledger.stats(
            by=request.by or "shift",
            since=convert.stats_bound(request.since, request.since_time, "since"),
            until=convert.stats_bound(request.until, request.until_time, "until"),
            codes=list(request.codes) or None, group_by=list(request.group_by),
            as_of=convert.stats_moment(request.as_of, "as_of"))
        response.success = True
        response.rows = [convert.stats_row_msg(row) for row in rows]
        return response

    def close(self) -> None:
        """Once the executor stopped (``serve`` first lets reads in flight finish)."""
        if self.report_loop is not None:
            self.report_loop.close()
        self.subscription.cancel()
        self._publish_guarded()
        self.reads.close()
        for service in self.services:
            self.node.destroy_service(service)
