"""Take the requests queued behind the one being served, so a burst shares one commit.

The fault manager spins a single-threaded executor (rclpy's multi-threaded one costs more per
call than group commit saves on small machines, bench/ros_report.py). While one report is
being made durable, others queue in the service's DDS reader; the report callback takes them
all, has the ledger commit them together, and answers each with ``Service.send_response``.
"""

from __future__ import annotations

from typing import Any

from rclpy.service import Service

MAX_TAKEN = 512
"""Most extra requests one callback takes (the ledger's default max_batch)."""


def take_queued(service: Service, limit: int = MAX_TAKEN) -> list[tuple[Any, Any]]:
    """(request, header) pairs already waiting on ``service``, oldest first."""
    taken: list[tuple[Any, Any]] = []
    request_type: Any = service.srv_type
    with service.handle:
        while len(taken) < limit:
            request, header = service.handle.service_take_request(request_type.Request)
            if header is None:
                break
            taken.append((request, header))
    return taken
