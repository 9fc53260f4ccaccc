"""Real rclpy action servers (``faultledger_test_actions/action/Count``, built by
tests/ros/count_action.py) and a client that sends them goals, in one process.

Usage: ``drive_count_action.py ACTION [ACTION ...]`` with the package importable (its
``environment``). Node ``/count_server`` serves every ACTION; node ``/count_client`` sends
the goals. The servers keep finished goals for rclpy's default result_timeout (900 s), so each
status array they publish carries every goal so far, as on a robot.

Commands on stdin, one JSON list per line:

* ``["goal", ACTION, OUTCOME]``: send one goal and wait for its result. OUTCOME is how the
  server ends it: ``succeed``, ``abort`` or ``cancel`` (the client requests the cancel once the
  goal executes). Answered ``goal <uuid> <STATUS>`` (``SUCCEEDED``, ``ABORTED``, ``CANCELED``)
  with the goal's id as UUID text.

EOF or SIGTERM: the nodes are destroyed and the process exits 0.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
import time
import uuid
from types import FrameType
from typing import Any

import rclpy
from action_msgs.msg import GoalStatus
from faultledger_test_actions.action import Count  # type: ignore[import-not-found]
from rclpy.action.client import ActionClient
from rclpy.action.server import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import try_shutdown

STATUS = {GoalStatus.STATUS_SUCCEEDED: "SUCCEEDED", GoalStatus.STATUS_ABORTED: "ABORTED",
          GoalStatus.STATUS_CANCELED: "CANCELED"}
WAIT_SEC = 20.0


def execute(goal_handle: Any) -> Any:
    outcome = goal_handle.request.outcome
    goal_handle.publish_feedback(Count.Feedback(step=1))
    if outcome == "cancel":
        deadline = time.monotonic() + WAIT_SEC
        while not goal_handle.is_cancel_requested and time.monotonic() < deadline:
            time.sleep(0.01)
        goal_handle.canceled()
    elif outcome == "abort":
        goal_handle.abort()
    else:
        goal_handle.succeed()
    return Count.Result(outcome=outcome)


def wait(future: Any, what: str) -> Any:
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(WAIT_SEC):
        raise TimeoutError(f"{what}: no answer within {WAIT_SEC} s")
    return future.result()


class Driver:
    def __init__(self, actions: list[str]) -> None:
        group = ReentrantCallbackGroup()
        self.server = Node("count_server")
        self.client = Node("count_client")
        self.servers = [ActionServer(
            self.server, Count, action, execute_callback=execute, callback_group=group,
            goal_callback=lambda _: GoalResponse.ACCEPT,
            cancel_callback=lambda _: CancelResponse.ACCEPT) for action in actions]
        self.clients = {action: ActionClient(self.client, Count, action, callback_group=group)
                        for action in actions}
        self.executor = MultiThreadedExecutor(num_threads=4)
        self.executor.add_node(self.server)
        self.executor.add_node(self.client)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        for action, client in self.clients.items():
            if not client.wait_for_server(timeout_sec=WAIT_SEC):
                raise TimeoutError(f"action server {action} not available")

    def goal(self, action: str, outcome: str) -> str:
        handle = wait(self.clients[action].send_goal_async(Count.Goal(outcome=outcome)),
                      "send_goal")
        if not handle.accepted:
            raise RuntimeError("goal rejected")
        if outcome == "cancel":
            wait(handle.cancel_goal_async(), "cancel_goal")
        result = wait(handle.get_result_async(), "get_result")
        goal_id = uuid.UUID(bytes=bytes(bytearray(handle.goal_id.uuid)))
        return f"goal {goal_id} {STATUS.get(result.status, result.status)}"

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2.0)
        for server in self.servers:
            server.destroy()
        for client in self.clients.values():
            client.destroy()
        self.server.destroy_node()
        self.client.destroy_node()


def main() -> int:
    rclpy.init(args=sys.argv, signal_handler_options=SignalHandlerOptions.NO)

    def on_signal(_signum: int, _frame: FrameType | None) -> None:
        raise SystemExit(0)  # unwinds the blocking read; finally leaves the graph cleanly

    signal.signal(signal.SIGTERM, on_signal)
    driver = Driver(sys.argv[1:])
    print(f"driver ready: {' '.join(sys.argv[1:])}", flush=True)
    try:
        for line in sys.stdin:
            verb, action, outcome = json.loads(line)
            if verb != "goal":
                raise ValueError(f"unknown command {line!r}")
            print(driver.goal(action, outcome), flush=True)
    finally:
        driver.close()
        try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
