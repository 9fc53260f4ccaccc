"""The baseline of bench/ros_report.py: a ReportFault service that answers accepted=True.

Same request type, QoS, callback group and executor (faultledger.ros.serve.make_executor) as the
fault manager, so the ratio isolates what faultledger adds: validation, the durable append and
the projections.
"""

from __future__ import annotations

import signal
import threading

import rclpy
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import try_shutdown
from ros2_medkit_msgs.srv import ReportFault

from faultledger.ros.node import SERVICE_QOS
from faultledger.ros.serve import make_executor, spin_until


def main() -> None:
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    node = Node("fault_manager")

    def echo(_request: ReportFault.Request, response: ReportFault.Response) -> ReportFault.Response:
        response.accepted = True
        return response

    node.create_service(ReportFault, "~/report_fault", echo, qos_profile=SERVICE_QOS,
                        callback_group=ReentrantCallbackGroup())
    executor = make_executor()
    executor.add_node(node)
    print("fault_manager ready: echo", flush=True)
    try:
        spin_until(executor, stop)
    finally:
        executor.shutdown()
        node.destroy_node()
        try_shutdown()


if __name__ == "__main__":
    main()
