"""node_state bridge: nodemon heartbeats (``/nodemon/state``) → faults (docs/bridges/node_state.md).

Subscribes to ``nodemon_msgs/NodeState`` and feeds every message, stamped with the steady
clock at receipt, to the pure ``NodeStateMonitor``; a steady-clock timer looks for silent
nodes. Message stamps and the wall clock are never used for the timeout: a node with a wrong
clock, or a clock jump on this machine, must not fake or hide a heartbeat loss.
"""

from __future__ import annotations

import importlib
import time
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, Field
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from faultledger.ros.bridges.node_state_mapping import (
    HEARTBEAT_TIMEOUT_SEC,
    BadMessage,
    NodeStateMonitor,
    Report,
    Severities,
)
from faultledger.ros.bridges.throttle import Throttle
from faultledger.ros.guard import guard_callback

if TYPE_CHECKING:
    from faultledger.ros.reporter import FaultReporter

NODE_NAME = "faultledger_node_state_bridge"
TOPIC = "/nodemon/state"
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                 reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
"""Publisher and subscribers of ``/nodemon/state``: RELIABLE, KEEP_LAST 100, VOLATILE."""

WARN_EVERY_SEC = 10.0
"""Bad messages are warned about at most this often (with a count of those held back)."""


def node_state_type() -> Any:
    """``nodemon_msgs.msg.NodeState``, imported by name: the generated package is untyped."""
    return importlib.import_module("nodemon_msgs.msg").NodeState


class Settings(BaseModel):
    """The bridge's YAML (config/node_state.yaml); defaults are the documented behaviour."""

    topic: str = Field(default=TOPIC, min_length=1)
    heartbeat_timeout_sec: float = Field(default=HEARTBEAT_TIMEOUT_SEC, gt=0)
    check_period_sec: float = Field(default=0.5, gt=0)
    error_severity: int = Field(default=2, ge=0, le=3)
    fatal_severity: int = Field(default=3, ge=0, le=3)
    warning_severity: int = Field(default=1, ge=0, le=3)
    heartbeat_lost_severity: int = Field(default=2, ge=0, le=3)


class Bridge:
    """One subscription and one steady timer on ``node``; reports through ``reporter``."""

    def __init__(self, node: Node, settings: Settings, reporter: FaultReporter) -> None:
        self._node = node
        self._reporter = reporter
        self._log = node.get_logger()
        self._monitor = NodeStateMonitor(
            settings.heartbeat_timeout_sec,
            Severities(error=settings.error_severity, fatal=settings.fatal_severity,
                       warning=settings.warning_severity,
                       heartbeat_lost=settings.heartbeat_lost_severity))
        self._throttle = Throttle(self._log.warning, WARN_EVERY_SEC)
        self._subscription = node.create_subscription(
            node_state_type(), settings.topic,
            guard_callback(self._on_state, self._log, settings.topic), QOS)
        self._timer = node.create_timer(
            settings.check_period_sec, guard_callback(self._check, self._log, "heartbeat check"),
            clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._log.info(f"node_state: watching {settings.topic}, heartbeat timeout "
                       f"{settings.heartbeat_timeout_sec:g} s")

    @property
    def monitor(self) -> NodeStateMonitor:
        return self._monitor

    def close(self) -> None:
        self._node.destroy_timer(self._timer)
        self._node.destroy_subscription(self._subscription)

    def _on_state(self, message: Any) -> None:
        now = time.monotonic()
        try:
            reports = self._monitor.on_message(
                message.nodename, int(message.state), now, package=message.package,
                nodetype=message.nodetype, machine_message=message.machine_message,
                human_message=message.human_message)
        except BadMessage as error:
            self._throttle.warn("bad_message", f"node_state: ignored {error}")
            return
        self._apply(reports)

    def _check(self) -> None:
        self._apply(self._monitor.check(time.monotonic()))

    def _apply(self, reports: list[Report]) -> None:
        for report in reports:
            if report.kind == "failed":
                self._reporter.report(report.code, report.severity, report.description,
                                      source_id=report.source_id)
                self._log.info(f"node_state: FAILED {report.code} ({report.description})")
            else:
                self._reporter.report_passed(report.code, source_id=report.source_id)
                self._log.info(f"node_state: PASSED {report.code}")
