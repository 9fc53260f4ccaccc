"""NodeStatePublisher: a node's lifecycle state as a heartbeat on ``/nodemon/state``.

The successor of nodemon's C++/Python publisher. The node_state bridge turns these heartbeats
into faults (ERROR, FATAL, WARNING, heartbeat loss) and ``faultledger nodes`` shows them live.
Every state change is published at once; a timer on the node repeats the current state every
``period_sec`` (1 s) with a fresh stamp, so a monitor can tell a silent node from a quiet one.
"""

from __future__ import annotations

import threading
from typing import Any

from rclpy.duration import Duration

from faultledger.ros.bridges.node_state import QOS, TOPIC, node_state_type
from faultledger.ros.bridges.node_state_mapping import (
    ERROR,
    FATAL,
    RECOVERING,
    RUNNING,
    STARTING,
    STOPPING,
    WARNING,
)
from faultledger.ros.guard import guard_callback


class NodeStatePublisher:
    """Publishes ``nodemon_msgs/NodeState`` for ``node``: starts in STARTING.

    ``set_*`` may be called from any thread; each publishes immediately and becomes the state
    the heartbeat repeats. ``send_warning`` publishes one WARNING and leaves the state as it
    was: the next heartbeat carries the previous state again.
    """

    def __init__(self, node: Any, package: str, nodetype: str, *, topic: str = TOPIC,
                 period_sec: float = 1.0) -> None:
        self._type = node_state_type()
        self._node = node
        self._nodename: str = node.get_fully_qualified_name()
        self._package = package
        self._nodetype = nodetype
        self._lock = threading.Lock()
        self._state = STARTING
        self._machine = ""
        self._human = ""
        self._publisher = node.create_publisher(self._type, topic, QOS)
        # A failing heartbeat (a destroyed publisher, a shut-down context) must never take the
        # user's node down with it: one log line, and the next beat tries again.
        self._timer = node.create_timer(
            period_sec, guard_callback(self._heartbeat, node.get_logger(), "nodemon heartbeat"))
        self._publish(STARTING, "", "")

    @property
    def state(self) -> int:
        """The sustained state the heartbeat repeats (never WARNING)."""
        return self._state

    def set_running(self) -> None:
        self._set(RUNNING, "", "")

    def set_error(self, machine_message: str = "", human_message: str = "") -> None:
        self._set(ERROR, machine_message, human_message)

    def set_recovering(self, machine_message: str = "", human_message: str = "") -> None:
        self._set(RECOVERING, machine_message, human_message)

    def set_fatal(self, machine_message: str = "", human_message: str = "") -> None:
        self._set(FATAL, machine_message, human_message)

    def set_stopping(self) -> None:
        """Announce a clean exit: a monitor treats the silence that follows as no loss."""
        self._set(STOPPING, "", "")

    def send_warning(self, machine_message: str = "", human_message: str = "") -> None:
        """One WARNING message; the state is unchanged."""
        self._publish(WARNING, machine_message, human_message)

    def wait_for_all_acked(self, timeout_sec: float = 1.0) -> bool:
        """Block until reliable subscribers have acknowledged everything published (or the
        timeout): call it after ``set_stopping`` before destroying the node, or the STOPPING
        message can die with the process."""
        return bool(self._publisher.wait_for_all_acked(Duration(seconds=timeout_sec)))

    def destroy(self) -> None:
        """Stop the heartbeat and remove the publisher from the node."""
        self._node.destroy_timer(self._timer)
        self._node.destroy_publisher(self._publisher)

    def _set(self, state: int, machine: str, human: str) -> None:
        with self._lock:
            self._state, self._machine, self._human = state, machine, human
        self._publish(state, machine, human)

    def _heartbeat(self) -> None:
        with self._lock:
            state, machine, human = self._state, self._machine, self._human
        self._publish(state, machine, human)

    def _publish(self, state: int, machine: str, human: str) -> None:
        message = self._type()
        message.time = self._node.get_clock().now().to_msg()
        message.nodename = self._nodename
        message.package = self._package
        message.nodetype = self._nodetype
        message.state = state
        message.machine_message = machine
        message.human_message = human
        self._publisher.publish(message)
