"""A stand-in for action servers: publishes ``action_msgs/GoalStatusArray`` on
``/<action>/_action/status`` the way rcl_action's status publisher does.

The bridge only reads the status topic, so publishing it by hand covers every array, including
ones no real server would send (no action type ships with the wheels; test_goal_outcomes.py
builds one for real rclpy ActionServers, drive_count_action.py). Like a real server this process
publishes RELIABLE + TRANSIENT_LOCAL with
KEEP_LAST 1, and each array carries every goal it remembers (finished goals included), stamped
with their acceptance time.

Usage: ``drive_action_server.py NODE_NAME [--ros-args -r __ns:=/robot1]``. Commands on stdin, one
JSON list per line; each is answered with ``ok <n>`` on stdout once done:

* ``["goals", ACTION, [[GOAL, STATUS], ...]]``: set these goals' statuses (GOAL is an int turned
  into the 16-byte uuid) and publish the whole array of the action's goals.
* ``["raw", ACTION, [[GOAL, STATUS], ...]]``: publish exactly this array (bad messages).
* ``["open", ACTION, "volatile"]``: create the action's publisher with VOLATILE durability (an
  incompatible publisher); the other commands create a TRANSIENT_LOCAL one when needed.
* ``["close", ACTION]``: destroy the action's publisher (the action vanishes).

EOF or SIGTERM: the node is destroyed and the process exits 0 (its publishers leave the graph).
"""

from __future__ import annotations

import json
import signal
import sys
from types import FrameType
from typing import Any

import rclpy
from action_msgs.msg import GoalStatus, GoalStatusArray
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args, try_shutdown


def qos(durability: DurabilityPolicy) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE, durability=durability)


class Driver:
    def __init__(self, node: Node) -> None:
        self.node = node
        self.publishers: dict[str, Any] = {}
        self.goals: dict[str, dict[int, tuple[int, Any]]] = {}  # action → goal → (status, stamp)

    def publisher(self, action: str, durability: DurabilityPolicy =
                  DurabilityPolicy.TRANSIENT_LOCAL) -> Any:
        if action not in self.publishers:
            self.publishers[action] = self.node.create_publisher(
                GoalStatusArray, f"{action}/_action/status", qos(durability))
        return self.publishers[action]

    def publish(self, action: str, goals: list[tuple[int, int, Any]]) -> None:
        message = GoalStatusArray()
        for goal, status, stamp in goals:
            entry = GoalStatus()
            entry.goal_info.goal_id.uuid = list(goal.to_bytes(16, "big"))
            entry.goal_info.stamp = stamp
            entry.status = status
            message.status_list.append(entry)
        self.publisher(action).publish(message)

    def handle(self, command: list[Any]) -> None:
        verb, action = command[0], command[1]
        now = self.node.get_clock().now().to_msg()
        if verb == "goals":
            known = self.goals.setdefault(action, {})
            for goal, status in command[2]:
                known[goal] = (status, known[goal][1] if goal in known else now)
            self.publish(action, [(g, s, t) for g, (s, t) in known.items()])
        elif verb == "raw":
            self.publish(action, [(g, s, now) for g, s in command[2]])
        elif verb == "open":
            self.publisher(action, DurabilityPolicy.VOLATILE if command[2] == "volatile"
                           else DurabilityPolicy.TRANSIENT_LOCAL)
        elif verb == "close":
            self.node.destroy_publisher(self.publishers.pop(action))
            self.goals.pop(action, None)
        else:
            raise ValueError(f"unknown command {command!r}")


def main() -> int:
    rclpy.init(args=sys.argv, signal_handler_options=SignalHandlerOptions.NO)
    args = remove_ros_args(sys.argv)
    node = Node(args[1])

    def on_signal(_signum: int, _frame: FrameType | None) -> None:
        raise SystemExit(0)  # unwinds the blocking read; finally leaves the graph cleanly

    signal.signal(signal.SIGTERM, on_signal)
    driver = Driver(node)
    print(f"driver ready as {node.get_fully_qualified_name()}", flush=True)
    try:
        for count, line in enumerate(sys.stdin, 1):
            driver.handle(json.loads(line))
            print(f"ok {count}", flush=True)
    finally:
        node.destroy_node()
        try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
