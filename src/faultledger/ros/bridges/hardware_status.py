"""Hardware status bridge: ros2_control ``HardwareStatus`` messages → edge-triggered faults.

The rclpy half: subscriptions (configured topics, plus every ``*/hardware_status`` topic of the
configured type when ``discover`` is on), the message type imported by name, and the reports.
What a message means is decided in ``hardware_status_mapping`` (pure, unit-tested); the contract
is ``docs/bridges/hardware_status.md``.
"""

from __future__ import annotations

import importlib
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from faultledger.ros.bridges.hardware_status_mapping import (
    DEFAULT_MESSAGE_TYPE,
    TOPIC_SUFFIX,
    HardwareStatusMapper,
    Settings,
    resolve_severities,
)
from faultledger.ros.bridges.throttle import Throttle
from faultledger.ros.guard import guard_callback
from faultledger.ros.reporter import FaultReporter

__all__ = ["NODE_NAME", "Bridge", "Settings", "import_message_type"]

NODE_NAME = "faultledger_hardware_status_bridge"


def import_message_type(name: str) -> Any:
    """``pkg/msg/Type`` → the message class (as rosidl_runtime_py does: import ``pkg.msg``)."""
    package, kind, type_name = name.split("/")
    module = importlib.import_module(f"{package}.{kind}")
    return getattr(module, type_name)


class Bridge:
    """Subscribes, maps each message, reports each transition; never blocks a callback."""

    def __init__(self, node: Node, settings: Settings, reporter: FaultReporter) -> None:
        self._node = node
        self._log = node.get_logger()
        self._reporter = reporter
        self._settings = settings
        self._throttle = Throttle(self._log.warning, settings.warn_interval_sec)
        severities = resolve_severities(settings.severities, self._log.warning)
        self._mapper = HardwareStatusMapper(settings, severities)
        self._type_name, self._type = self._message_type(settings.message_type)
        self._qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=settings.queue_depth,
                               reliability=ReliabilityPolicy.RELIABLE,
                               durability=DurabilityPolicy.VOLATILE)
        self._subscriptions: dict[str, Any] = {}
        self._timer: Any = None
        if self._type is None:
            return
        for topic in settings.topics:
            self._subscribe(topic)
        if settings.discover:
            self._scan()
            self._timer = node.create_timer(settings.rescan_period_sec,
                                            guard_callback(self._scan, self._log, "rescan"))

    def _message_type(self, name: str) -> tuple[str, Any]:
        """The configured type; if it cannot be imported, ours (with an error naming it)."""
        for candidate in dict.fromkeys((name, DEFAULT_MESSAGE_TYPE)):
            try:
                return candidate, import_message_type(candidate)
            except (ImportError, AttributeError, ValueError) as error:
                self._log.error(f"hardware_status.message_type={candidate!r} cannot be imported "
                                f"({error}); " + ("using " + DEFAULT_MESSAGE_TYPE
                                                  if candidate != DEFAULT_MESSAGE_TYPE
                                                  else "the bridge subscribes to nothing"))
        return name, None

    def _subscribe(self, topic: str) -> None:
        if topic in self._subscriptions:
            return
        try:
            self._subscriptions[topic] = self._node.create_subscription(
                self._type, topic, guard_callback(self._on_message, self._log, topic),
                self._qos)
        except Exception as error:  # an invalid topic name in the config must not stop us
            self._throttle.warn(f"subscribe:{topic}", f"cannot subscribe to {topic!r}: {error}")
            return
        self._log.info(f"subscribed to {topic} ({self._type_name})")

    def _scan(self) -> None:
        """Subscribe to each new ``*/hardware_status`` topic carrying our type."""
        for topic, types in self._node.get_topic_names_and_types():
            if topic.endswith(TOPIC_SUFFIX) and self._type_name in types:
                self._subscribe(topic)

    def _on_message(self, message: Any) -> None:
        try:
            transitions, warnings = self._mapper.update(message)
        except Exception as error:  # a malformed message costs a warning, never the bridge
            self._throttle.warn("bad_message", f"HardwareStatus message ignored: {error!r}")
            return
        for key, text in warnings:
            self._throttle.warn(key, text)
        for t in transitions:
            if t.failed:
                self._log.info(f"FAILED {t.code} (severity {t.severity}): {t.description}")
                self._reporter.report(t.code, t.severity, t.description, source_id=t.source_id)
            else:
                self._log.info(f"PASSED {t.code}")
                self._reporter.report_passed(t.code, source_id=t.source_id)

    def close(self) -> None:
        if self._timer is not None:
            self._node.destroy_timer(self._timer)
            self._timer = None
        for subscription in self._subscriptions.values():
            self._node.destroy_subscription(subscription)
        self._subscriptions.clear()
