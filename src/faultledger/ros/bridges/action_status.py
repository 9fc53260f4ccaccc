"""Action-status bridge: every ``*/_action/status`` → ``<PREFIX>_<ACTION>_ABORTED``/``_CANCELED``,
and one goal outcome record per finished goal.

Works for any action server (Nav2, MoveIt 2, ros2_control controllers, custom ones) because it
only reads the standard status topic. Actions are found by scanning the graph every
``rescan_period_sec``; an action whose status topic has no publisher any more is dropped (and
healed first when it was failed and healing is on). The mapping itself lives in
``action_status_mapping`` (pure, unit-tested); reference: docs/bridges/action_status.md.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from action_msgs.msg import GoalStatusArray
from pydantic import BaseModel, Field
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from faultledger.ros.bridges.action_status_mapping import (
    STATUS_NAMES,
    STATUS_TYPE,
    TERMINAL,
    WHOLE_ARRAY,
    ActionTracker,
    Goal,
    GoalOutcome,
    Judge,
    RecordedGoals,
    Rules,
    SeenGoals,
    Transition,
    action_of_topic,
    goal_text,
    is_watched,
    status_name,
)
from faultledger.ros.bridges.codes import UPPER_SNAKE, upper_snake
from faultledger.ros.guard import guard_callback
from faultledger.ros.reporter import FaultReporter

NODE_NAME = "faultledger_action_status_bridge"

UNKNOWN_NAME = "_NODE_NAME_UNKNOWN_"
UNKNOWN_NAMESPACE = "_NODE_NAMESPACE_UNKNOWN_"
"""What the graph tells about a publisher whose node it has not discovered yet."""

SOURCE_WAIT_SEC = 5.0
"""How long reports of an action wait for its server's node name before falling back to the
action name as source_id (the node name usually follows the endpoint within milliseconds)."""

PENDING_CHECK_SEC = 0.25

STATUS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=10,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""What rcl_action's status publisher offers (reliable, transient local): a late bridge still
gets each server's latest array."""


class Settings(BaseModel):
    """config/action_status.yaml; docs/bridges/action_status.md."""

    rescan_period_sec: float = Field(default=2.0, gt=0)
    code_prefix: str = Field(default="ACTION", max_length=32,
                             pattern=rf"^{UPPER_SNAKE.pattern}$")
    aborted_severity: int = Field(default=2, ge=0, le=3)
    canceled_is_fault: bool = False
    heal_on_succeeded: bool = True
    judge: Judge = WHOLE_ARRAY
    exclude_actions: list[str] = Field(default_factory=list)
    include_only_actions: list[str] = Field(default_factory=list)
    dedup_capacity: int = Field(default=4096, ge=1)

    @classmethod
    def prepare_settings(cls, values: dict[str, Any], warn: Callable[[str], None]) -> None:
        """A ``code_prefix`` not in upper snake case (``acc-d``, ``Nav Stack``) is converted
        with a warning (``ACC_D``, ``NAV_STACK``); one with nothing to convert is left to
        validation (default with a warning)."""
        value = values.get("code_prefix")
        if isinstance(value, str) and not UPPER_SNAKE.fullmatch(value):
            converted = upper_snake(value)
            if converted:
                warn(f"code_prefix={value!r} is not upper snake case; using {converted!r}")
                values["code_prefix"] = converted


def node_fqn(namespace: str, name: str) -> str:
    return f"{namespace.rstrip('/')}/{name}"


@dataclass
class _Pending:
    """Transitions and goal outcomes of one action waiting for its server's name (in order)."""

    since: float
    transitions: list[Transition] = field(default_factory=list)
    outcomes: list[GoalOutcome] = field(default_factory=list)


class Bridge:
    """Subscriptions to the status topics found on the graph, and the tracker deciding edges."""

    def __init__(self, node: Node, settings: Settings, reporter: FaultReporter) -> None:
        self._node = node
        self._log = node.get_logger()
        self._settings = settings
        self._reporter = reporter
        self._tracker = ActionTracker(Rules(settings.code_prefix, settings.aborted_severity,
                                            settings.canceled_is_fault,
                                            settings.heal_on_succeeded, settings.judge))
        self._seen = SeenGoals(settings.dedup_capacity)
        self._recorded = RecordedGoals(settings.dedup_capacity)
        self._subscriptions: dict[str, Any] = {}
        self._sources: dict[str, str] = {}  # action → its server's node FQN, once known
        self._pending: dict[str, _Pending] = {}
        self._skipped: set[str] = set()  # filtered-out actions, logged once
        self._rescan()
        self._timer = node.create_timer(
            settings.rescan_period_sec, guard_callback(self._rescan, self._log, "rescan"))
        self._pending_timer = node.create_timer(
            PENDING_CHECK_SEC, guard_callback(self._flush_all, self._log, "pending reports"))

    def close(self) -> None:
        self._node.destroy_timer(self._timer)
        self._node.destroy_timer(self._pending_timer)
        for subscription in self._subscriptions.values():
            self._node.destroy_subscription(subscription)
        self._subscriptions.clear()

    # -- discovery --------------------------------------------------------------------------------
    def _rescan(self) -> None:
        """Subscribe to new status topics, drop those without a publisher any more."""
        alive: dict[str, str | None] = {}  # action → server FQN (None: not known yet)
        for topic, types in self._node.get_topic_names_and_types():
            action = action_of_topic(topic)
            if action is None or STATUS_TYPE not in types:
                continue
            if not is_watched(action, self._settings.exclude_actions,
                              self._settings.include_only_actions):
                if action not in self._skipped:
                    self._skipped.add(action)
                    self._log.info(f"action {action} is filtered out; not watched")
                continue
            has_publisher, server = self._server(topic)
            if has_publisher:
                alive[action] = server
        for action in [a for a in self._subscriptions if a not in alive]:
            self._drop(action)
        for action, server in alive.items():
            if server is not None:
                self._sources[action] = server
            if action not in self._subscriptions:
                self._watch(action)

    def _server(self, topic: str) -> tuple[bool, str | None]:
        """Whether ``topic`` has a publisher, and the FQN of its node when the graph knows it."""
        publishers = self._node.get_publishers_info_by_topic(topic)
        known = sorted(node_fqn(p.node_namespace, p.node_name) for p in publishers
                       if p.node_name != UNKNOWN_NAME and p.node_namespace != UNKNOWN_NAMESPACE)
        return bool(publishers), (known[0] if known else None)

    def _watch(self, action: str) -> None:
        def on_incompatible(info: Any) -> None:
            self._log.warning(
                f"action {action}: a status publisher offers QoS incompatible with reliable + "
                f"transient_local (policy {info.last_policy_kind}, {info.total_count} so far); "
                f"its goal statuses are not received")

        def on_status(message: Any) -> None:
            self._on_status(action, message)

        name = f"{action}/_action/status"
        self._subscriptions[action] = self._node.create_subscription(
            GoalStatusArray, name, guard_callback(on_status, self._log, name), STATUS_QOS,
            event_callbacks=SubscriptionEventCallbacks(
                incompatible_qos=guard_callback(on_incompatible, self._log, name)))
        server = self._sources.get(action, "not known yet")
        self._log.info(f"watching action {action} (server {server})")

    def _drop(self, action: str) -> None:
        subscription = self._subscriptions.pop(action)
        self._node.destroy_subscription(subscription)
        self._report(action, self._tracker.drop(action))
        self._flush(action, force=True)
        self._sources.pop(action, None)
        self._log.info(f"action {action} vanished; no longer watched")

    # -- status arrays ----------------------------------------------------------------------------
    def _on_status(self, action: str, message: Any) -> None:
        received_ns = time.time_ns()
        goals: list[Goal] = []
        for goal in message.status_list:
            goal_id = bytes(bytearray(goal.goal_info.goal_id.uuid))
            status = int(goal.status)
            goals.append((goal_id, status))
            self._note(action, goal_id, status)
        self._report(action, self._tracker.observe(action, goals),
                     self._recorded.new_outcomes(action, goals, received_ns))

    def _note(self, action: str, goal_id: bytes, status: int) -> None:
        """Log each goal's terminal (or invalid) status once."""
        if status in STATUS_NAMES and status not in TERMINAL:
            return
        if not self._seen.first_time(action, goal_id, status):
            return
        text = f"action {action}: goal {goal_text(goal_id)} {status_name(status)}"
        if status not in STATUS_NAMES:
            self._log.warning(f"{text}: not a GoalStatus value; ignored")
        else:
            self._log.info(text)

    # -- reports --------------------------------------------------------------------------------
    def _report(self, action: str, transitions: list[Transition],
                outcomes: list[GoalOutcome] | None = None) -> None:
        """Send now when the server's name is known, else hold (in order) until it is."""
        if transitions or outcomes:
            pending = self._pending.setdefault(action, _Pending(time.monotonic()))
            pending.transitions.extend(transitions)
            pending.outcomes.extend(outcomes or ())
        self._flush(action)

    def _flush_all(self) -> None:
        for action in list(self._pending):
            self._flush(action)

    def _flush(self, action: str, force: bool = False) -> None:
        pending = self._pending.get(action)
        if pending is None:
            return
        source = self._sources.get(action)
        if source is None:
            source = self._server(f"{action}/_action/status")[1]
            if source is not None:
                self._sources[action] = source
        server = source or ""  # goal outcomes: empty when the server's node is not known
        if source is None:
            if not force and time.monotonic() - pending.since < SOURCE_WAIT_SEC:
                return
            source = action
            self._log.warning(f"action {action}: the node of its server is not known; "
                              f"reporting with source_id {action} (goal outcomes without a "
                              f"server node)")
        del self._pending[action]
        for outcome in pending.outcomes:
            self._reporter.report_goal_outcome(outcome.action, outcome.goal_id, outcome.status,
                                               server_node=server, stamp_ns=outcome.stamp_ns)
        for transition in pending.transitions:
            if transition.passed:
                self._reporter.report_passed(transition.code, source_id=source)
                self._log.info(f"{transition.code} PASSED ({action} healthy again)")
            else:
                self._reporter.report(transition.code, transition.severity,
                                      transition.description, source_id=source)
                self._log.warning(f"{transition.code} FAILED: {transition.description}")
