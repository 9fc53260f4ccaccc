"""The `fault_manager` node: ROS services and the events topic over one FaultLedger.

Callbacks only translate: request → FaultLedger call → response. A report callback also takes
the reports queued behind its own (service_queue.py), so a burst from many clients shares
group commits although the executor runs one callback at a time.
"""

from __future__ import annotations

import logging
from typing import Any

from faultledger_msgs.srv import GetHistory, GetStatistics, ReportFaultOnce
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.service import Service
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
from faultledger.errors import FaultLedgerError
from faultledger.ros import convert
from faultledger.ros.service_queue import take_queued
from faultledger.service.ledger import FaultLedger
from faultledger.service.requests import ReportRequest
from faultledger.service.results import ReportResult

log = logging.getLogger(__name__)

NODE_NAME = "fault_manager"
SERVICE_QUEUE_DEPTH = 10_000
"""Requests a service keeps queued: above any burst we test (4 clients x 500), so a fault
storm is answered instead of silently dropped (the default depth is 10)."""
HISTORY_LIMIT = 10_000
"""Most records one get_history answer carries; page with since/until."""

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


class FaultManagerNode:
    """Services and publisher of `/fault_manager`, bound to an open ledger."""

    def __init__(self, node: Node, ledger: FaultLedger) -> None:
        self.node = node
        self.ledger = ledger
        self.events = node.create_publisher(FaultEvent, "~/events", EVENTS_QOS)
        self.report_service = node.create_service(
            ReportFault, "~/report_fault", self.report_fault, qos_profile=SERVICE_QOS)
        self.report_once_service = node.create_service(
            ReportFaultOnce, "~/report_fault_once", self.report_fault_once,
            qos_profile=SERVICE_QOS)
        services: list[tuple[Any, str, Any]] = [
            (ListFaults, "~/list_faults", self.list_faults),
            (GetFault, "~/get_fault", self.get_fault),
            (ClearFault, "~/clear_fault", self.clear_fault),
            (ListFaultsForEntity, "~/list_faults_for_entity", self.list_faults_for_entity),
            (GetHistory, "~/get_history", self.get_history),
            (GetStatistics, "~/get_statistics", self.get_statistics),
        ]
        self.services = [self.report_service, self.report_once_service, *(
            node.create_service(kind, name, callback, qos_profile=SERVICE_QOS)
            for kind, name, callback in services)]
        self.subscription = ledger.subscribe(self.publish)

    def publish(self, notification: Notification) -> None:
        """Called by the ledger after the change is durable, in log order."""
        self.events.publish(convert.event_msg(notification))

    def report_fault(self, request: Any, response: Any) -> Any:
        return self._report_burst(self.report_service, request, response, idempotent=False)

    def report_fault_once(self, request: Any, response: Any) -> Any:
        return self._report_burst(self.report_once_service, request, response, idempotent=True)

    def _report_burst(self, service: Service, request: Any, response: Any,
                      idempotent: bool) -> Any:
        """Make this report and every one queued behind it durable in shared commits."""
        queued = take_queued(service)
        requests = [request, *(r for r, _ in queued)]
        results = self.ledger.report_many([
            ReportRequest(r.fault_code, r.event_type, r.severity, r.description, r.source_id,
                          event_id=r.event_id if idempotent else None)
            for r in requests])
        for r, result in zip(requests, results, strict=True):
            if not result.accepted:
                self.node.get_logger().warning(
                    f"report of {r.fault_code!r} from {r.source_id!r} rejected: "
                    f"{result.message}")
        kind: Any = service.srv_type
        for (_, header), result in zip(queued, results[1:], strict=True):
            service.send_response(self._answer(kind.Response(), result), header)
        return self._answer(response, results[0])

    @staticmethod
    def _answer(response: Any, result: ReportResult) -> Any:
        response.accepted = result.accepted
        if hasattr(response, "duplicate"):  # ReportFaultOnce
            response.duplicate = result.duplicate
            response.message = "" if result.accepted else result.message
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

    def list_faults_for_entity(self, request: Any, response: Any) -> Any:
        lookup = self.ledger.lookup_entity(request.entity_id)
        response.success = lookup.success
        response.error_message = lookup.message
        response.faults = [convert.fault_msg(f) for f in lookup.faults]
        return response

    def get_history(self, request: Any, response: Any) -> Any:
        since, until = convert.from_time(request.since), convert.from_time(request.until)
        limit = min(request.limit or HISTORY_LIMIT, HISTORY_LIMIT)
        try:
            records = self.ledger.history(
                code=request.fault_code or None, source=request.source_id or None,
                since=since or None, until=until or None,
                kinds=list(request.kinds), limit=limit)
        except FaultLedgerError as error:
            response.success = False
            response.error_message = str(error)
            return response
        response.success = True
        response.records = [convert.record_msg(r) for r in records]
        return response

    def get_statistics(self, request: Any, response: Any) -> Any:
        """``FaultLedger.stats`` in the ledger's calendar; refused input → success=false."""
        try:
            rows = self.ledger.stats(
                by=request.by or "shift",
                since=convert.stats_bound(request.since, request.since_time, "since"),
                until=convert.stats_bound(request.until, request.until_time, "until"),
                codes=list(request.codes) or None, group_by=list(request.group_by),
                as_of=convert.stats_moment(request.as_of, "as_of"))
        except FaultLedgerError as error:
            response.success = False
            response.message = str(error)
            return response
        response.success = True
        response.rows = [convert.stats_row_msg(row) for row in rows]
        return response

    def close(self) -> None:
        self.subscription.cancel()
        for service in self.services:
            self.node.destroy_service(service)
