"""The baselines of bench/ros_report.py: a ReportFault service that answers accepted=True.

``echo``: a node with that one service. Same request type, QoS, callback group and executor
(faultledger.ros.serve.make_executor) as the fault manager, so the ratio isolates what
faultledger adds: validation, the durable append, the projections, and the rest of its node.

``shaped DB``: the fault manager's own node (FaultManagerNode on a scratch ledger at DB: all
its services, the read pool, the events publisher, the report loop) with only
``report_fault``'s callback replaced by the echo. The ratio against it isolates what a report
itself costs; its difference from ``echo`` is what the node's serving saves or costs per call
against rclpy's executor (the report loop answers without the executor: faster).
"""

from __future__ import annotations

import signal
import sys
import threading
from typing import Any

import rclpy
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import try_shutdown
from ros2_medkit_msgs.srv import ReportFault

from faultledger import FaultLedger
from faultledger.ros.node import NODE_NAME, SERVICE_QOS, FaultManagerNode
from faultledger.ros.serve import make_executor, spin_until


def echo(_request: ReportFault.Request, response: ReportFault.Response) -> ReportFault.Response:
    response.accepted = True
    return response


def main() -> None:
    shaped = sys.argv[1:2] == ["shaped"]
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    node = Node(NODE_NAME)
    ledger: FaultLedger | None = None
    manager: Any = None
    if shaped:
        ledger = FaultLedger.open(f"sqlite:///{sys.argv[2]}")
        manager = FaultManagerNode(node, ledger)
        manager.report_service.callback = echo  # read by the report loop per request
    else:
        node.create_service(ReportFault, "~/report_fault", echo, qos_profile=SERVICE_QOS,
                            callback_group=ReentrantCallbackGroup())
    executor = make_executor()
    executor.add_node(node)
    print(f"fault_manager ready: {'shaped echo' if shaped else 'echo'}", flush=True)
    try:
        spin_until(executor, stop)
    finally:
        executor.shutdown()
        if manager is not None:
            manager.close()
        node.destroy_node()
        if ledger is not None:
            ledger.close()
        try_shutdown()


if __name__ == "__main__":
    main()
