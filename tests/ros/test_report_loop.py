"""The report loop (faultledger.ros.report_loop) serves its services with no executor at all.

A server node in this test process is added to no executor: every answer comes from the
loop's thread. The client is the usual RosClient (its own node and executor).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from itertools import count
from typing import TYPE_CHECKING, Any

import pytest
from rclpy.node import Node
from ros2_medkit_msgs.srv import ReportFault

from faultledger.ros.node import SERVICE_QOS
from faultledger.ros.report_loop import ReportLoop, detached_service

if TYPE_CHECKING:
    from tests.ros.conftest import RosClient

_names = count()


class Server:
    """A node, in no executor, with one detached ReportFault service and its loop."""

    def __init__(self, client: RosClient, callback: Any) -> None:
        self.name = f"loop_server_{os.getpid()}_{next(_names)}"
        self.node = Node(self.name, context=client.context)
        self.service_name = f"/{self.name}/report_fault"
        self.published = threading.Event()
        self.service = detached_service(self.node, ReportFault, "~/report_fault", callback,
                                        SERVICE_QOS)
        self.loop = ReportLoop(self.node, [self.service], self.node.get_logger(),
                               after=self.published.set)

    def close(self) -> None:
        self.loop.close()
        self.node.destroy_node()


@pytest.fixture
def make_server(client: RosClient) -> Iterator[Any]:
    servers: list[Server] = []

    def make(callback: Any) -> Server:
        servers.append(Server(client, callback))
        return servers[-1]

    yield make
    for server in servers:
        server.close()


def request(code: str) -> Any:
    return ReportFault.Request(fault_code=code, event_type=0, severity=1,
                               description="loop", source_id="/loop_test")


def test_the_loop_answers_without_an_executor_and_runs_after(client: RosClient,
                                                             make_server: Any) -> None:
    codes: list[str] = []

    def accept(req: Any, response: Any) -> Any:
        codes.append(req.fault_code)
        response.accepted = threading.current_thread().name == "fault_manager_reports"
        return response

    server = make_server(accept)
    answers = [client.call(ReportFault, server.service_name, request(f"LOOP_{i}"))
               for i in range(5)]
    assert [a.accepted for a in answers] == [True] * 5  # answered on the loop's thread
    assert codes == [f"LOOP_{i}" for i in range(5)]
    assert server.published.is_set()
    # Not an entity of the node for any executor, but listed under the node in the graph.
    assert server.service not in list(server.node.services)
    assert client.spin_until(lambda: (server.service_name, ["ros2_medkit_msgs/srv/ReportFault"])
                             in client.node.get_service_names_and_types_by_node(
                                 server.name, "/"), 10.0)


def test_a_callback_that_raises_costs_its_answer_not_the_loop(client: RosClient,
                                                              make_server: Any) -> None:
    def picky(req: Any, response: Any) -> Any:
        if req.fault_code == "BOOM":
            raise RuntimeError("callback failed")
        response.accepted = True
        return response

    server = make_server(picky)
    assert client.call(ReportFault, server.service_name, request("BEFORE")).accepted
    with pytest.raises(AssertionError, match="no answer within"):  # ServiceTimeout
        client.call(ReportFault, server.service_name, request("BOOM"), timeout=1.0)
    assert client.call(ReportFault, server.service_name, request("AFTER")).accepted


def test_close_stops_the_thread_and_removes_the_service(client: RosClient,
                                                        make_server: Any) -> None:
    def accept(_req: Any, response: Any) -> Any:
        response.accepted = True
        return response

    server = make_server(accept)
    assert client.call(ReportFault, server.service_name, request("ONCE")).accepted
    server.loop.close()
    assert not any(t.name == "fault_manager_reports" and t.ident == server.loop.thread_id
                   for t in threading.enumerate())
    # By node: the name alone stays in the graph while our client for it exists.
    assert client.spin_until(lambda: server.service_name not in dict(
        client.node.get_service_names_and_types_by_node(server.name, "/")), 10.0)
