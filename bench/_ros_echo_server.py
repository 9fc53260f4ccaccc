"""The baselines of bench/ros_report.py: a ReportFault service that answers accepted=True.

``echo``: a node with that one service. Same request type, QoS, callback group and executor
(faultledger.ros.serve.make_executor) as the fault manager, so the ratio isolates what
faultledger adds: validation, the durable append, the projections, and the rest of its node.

``shaped DB``: the fault manager's own node (FaultManagerNode on a scratch ledger at DB: all
its services, the read pool, the events publisher, the report loop) with only
``report_fault``'s callback replaced by the echo. The ratio against it isolates what a report
itself costs; its difference from ``echo`` is what the node's serving saves or costs per call
against rclpy's executor (the report loop answers without the executor: faster).

``committing DB``: the shaped node whose ``report_fault`` first appends the report with raw
sqlite3 as bench/ingest.py's baseline (a) does (its table in a file beside DB), then answers;
the requests queued behind it share its durable commit, as in the fault manager's node. The
physical limit measured as one server instead of a sum: the fault manager's own ROS path
around the cheapest durable commit there is. The ratio against it is what faultledger's
report costs beyond raw sqlite3 inside ``serve``.
"""

from __future__ import annotations

import signal
import sqlite3
import statistics
import sys
import threading
import time
from pathlib import Path
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
from faultledger.ros.service_queue import take_queued
from ingest import RAW_INSERT, RAW_SCHEMA, raw_row


def echo(_request: ReportFault.Request, response: ReportFault.Response) -> ReportFault.Response:
    response.accepted = True
    return response


class RawCommit:
    """(a) of bench/ingest.py: per report the payload's JSON and the chained hash, one row;
    the requests queued behind the one served are taken and share its fsync'd commit (WAL,
    synchronous=FULL), as the fault manager's own ``report_fault`` does (group commit)."""

    def __init__(self, db: Path) -> None:
        self.conn = sqlite3.connect(db, isolation_level=None, check_same_thread=False)
        assert self.conn.execute("PRAGMA journal_mode = WAL").fetchone()[0] == "wal"
        self.conn.execute("PRAGMA synchronous = FULL")
        self.conn.execute(RAW_SCHEMA)
        self.seq = 0
        self.prev = "0" * 64
        self.service: Any = None
        self.commit_s: list[float] = []
        """How long each COMMIT took inside the node (printed at exit)."""

    def __call__(self, request: ReportFault.Request,
                 response: ReportFault.Response) -> ReportFault.Response:
        queued = take_queued(self.service)
        self.conn.execute("BEGIN IMMEDIATE")
        for r in [request, *(r for r, _ in queued)]:
            self.seq += 1
            row = raw_row(self.seq, self.prev, r.fault_code, r.event_type, r.source_id,
                          r.severity, r.description)
            self.prev = row[-1]
            self.conn.execute(RAW_INSERT, row)
        started = time.perf_counter()
        self.conn.execute("COMMIT")
        self.commit_s.append(time.perf_counter() - started)
        for _, header in queued:
            answer = ReportFault.Response()
            answer.accepted = True
            self.service.send_response(answer, header)
        response.accepted = True
        return response


def main() -> None:
    mode = sys.argv[1] if len(sys.argv) > 1 else "echo"
    shaped = mode in ("shaped", "committing")
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    node = Node(NODE_NAME)
    ledger: FaultLedger | None = None
    manager: Any = None
    callback: Any = echo
    if shaped:
        ledger = FaultLedger.open(f"sqlite:///{sys.argv[2]}")
        manager = FaultManagerNode(node, ledger)
        if mode == "committing":
            callback = RawCommit(Path(f"{sys.argv[2]}.raw"))
            callback.service = manager.report_service
        manager.report_service.callback = callback  # read by the report loop per request
    else:
        node.create_service(ReportFault, "~/report_fault", echo, qos_profile=SERVICE_QOS,
                            callback_group=ReentrantCallbackGroup())
    executor = make_executor()
    executor.add_node(node)
    print(f"fault_manager ready: {mode}", flush=True)
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
    if isinstance(callback, RawCommit) and callback.commit_s:
        print(f"commit median {statistics.median(callback.commit_s) * 1e3:.4f} ms", flush=True)


if __name__ == "__main__":
    main()
