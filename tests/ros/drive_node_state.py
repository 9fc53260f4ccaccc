"""A node with a NodeStatePublisher, driven over stdin by tests/ros/test_bridge_node_state.py.

``python drive_node_state.py NAME NAMESPACE [--ros-args ...]`` prints ``ready <fqn>`` once up,
then reads one command per line and answers ``ok <command>`` after it:

* ``running`` / ``stopping``; ``error|recovering|fatal|warning MACHINE HUMAN...``;
* ``bad STATE NODENAME`` publishes a raw NodeState (e.g. state 42) on the same topic;
* ``exit``: wait until subscribers acknowledged what was sent, then exit 0 (EOF: the same).
"""

from __future__ import annotations

import select
import sys


def main() -> int:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from faultledger.nodemon import NodeStatePublisher
    from faultledger.ros.bridges.node_state import QOS, TOPIC, node_state_type

    name, namespace = sys.argv[1], sys.argv[2]
    context = Context()
    rclpy.init(args=sys.argv, context=context)
    node = rclpy.create_node(name, namespace=namespace, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    states = NodeStatePublisher(node, "faultledger_tests", "drive_node_state")
    raw = node.create_publisher(node_state_type(), TOPIC, QOS)
    print("ready", node.get_fully_qualified_name(), flush=True)
    try:
        while True:
            executor.spin_once(timeout_sec=0.02)
            if not select.select([sys.stdin], [], [], 0)[0]:
                continue
            line = sys.stdin.readline()
            command, *rest = line.split(" ", 2) if line.strip() else ["exit"]
            command = command.strip()
            machine = rest[0].strip() if rest else ""
            human = rest[1].strip() if len(rest) > 1 else ""
            if command == "exit":
                states.wait_for_all_acked(2.0)
                print("ok exit", flush=True)
                return 0
            if command == "running":
                states.set_running()
            elif command == "stopping":
                states.set_stopping()
            elif command == "error":
                states.set_error(machine, human)
            elif command == "recovering":
                states.set_recovering(machine, human)
            elif command == "fatal":
                states.set_fatal(machine, human)
            elif command == "warning":
                states.send_warning(machine, human)
            elif command == "bad":
                message = node_state_type()()
                message.state = int(machine)
                message.nodename = human
                raw.publish(message)
            else:
                print(f"unknown command {command!r}", file=sys.stderr, flush=True)
                return 2
            print("ok", command, flush=True)
    finally:
        states.destroy()
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
