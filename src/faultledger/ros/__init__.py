"""ROS 2 adapter: the fault manager node and the FaultReporter client (needs rclpy)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from faultledger.ros.reporter import FaultReporter

__all__ = ["FaultReporter"]


def __getattr__(name: str) -> Any:
    """Import rclpy only when a ROS piece is used, so the core works without ROS installed."""
    if name == "FaultReporter":
        from faultledger.ros.reporter import FaultReporter

        return FaultReporter
    raise AttributeError(name)
