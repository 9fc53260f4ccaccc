"""Diagnostics bridge: ``/diagnostics`` (diagnostic_msgs/DiagnosticArray) levels → faults.

OK → PASSED, WARN → WARN, ERROR → ERROR, STALE → CRITICAL (severities configurable), reported
only when a status's level changes (``diagnostics_mapping.EdgeTracker``): diagnostics repeat
every status about once a second and the fault log must not fill with samples. Reference:
docs/bridges/diagnostics.md.
"""

from __future__ import annotations

from typing import Any

from diagnostic_msgs.msg import DiagnosticArray  # type: ignore[import-untyped,unused-ignore]
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from faultledger.ros.bridges.diagnostics_mapping import EdgeTracker, Settings
from faultledger.ros.bridges.throttle import Throttle
from faultledger.ros.guard import guard_callback
from faultledger.ros.reporter import FaultReporter

__all__ = ["NODE_NAME", "Bridge", "Settings"]

NODE_NAME = "faultledger_diagnostics_bridge"


class Bridge:
    """Subscribes to the diagnostics topic and reports level changes through ``reporter``."""

    def __init__(self, node: Node, settings: Settings, reporter: FaultReporter) -> None:
        self._node = node
        self._reporter = reporter
        log = node.get_logger()
        self._warn = Throttle(log.warning, settings.warn_interval_sec).warn
        self._tracker = EdgeTracker(settings, node.get_fully_qualified_name(), self._warn)
        reliability = (ReliabilityPolicy.BEST_EFFORT if settings.reliability == "best_effort"
                       else ReliabilityPolicy.RELIABLE)
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=settings.queue_depth,
                         reliability=reliability, durability=DurabilityPolicy.VOLATILE)
        self._subscription = node.create_subscription(
            DiagnosticArray, settings.topic, guard_callback(self._on_array, log, settings.topic),
            qos)
        log.info(f"diagnostics bridge: listening on {self._subscription.topic_name}")

    def _on_array(self, message: Any) -> None:
        """Never raises: a bad message is warned about, the bridge keeps running."""
        try:
            reports = self._tracker.process(message.status)
        except Exception as error:  # a malformed message must not end the bridge
            self._warn("exception", f"diagnostics: message skipped: {error!r}")
            return
        for report in reports:
            if report.passed:
                self._reporter.report_passed(report.code, source_id=report.source_id)
            else:
                self._reporter.report(report.code, report.severity, report.description,
                                      source_id=report.source_id)

    def close(self) -> None:
        self._node.destroy_subscription(self._subscription)
