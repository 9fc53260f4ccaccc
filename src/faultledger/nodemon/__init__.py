"""nodemon: the node-state heartbeat a node publishes on ``/nodemon/state`` (needs rclpy).

``NodeStatePublisher`` is imported lazily, so ``import faultledger.nodemon`` (and the state
constants) work without ROS installed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from faultledger.ros.bridges.node_state_mapping import (
    ERROR,
    FATAL,
    RECOVERING,
    RUNNING,
    STARTING,
    STATE_NAMES,
    STOPPING,
    WARNING,
)

if TYPE_CHECKING:
    from faultledger.nodemon.publisher import NodeStatePublisher

__all__ = ["ERROR", "FATAL", "RECOVERING", "RUNNING", "STARTING", "STATE_NAMES", "STOPPING",
           "WARNING", "NodeStatePublisher"]


def __getattr__(name: str) -> Any:
    """Import rclpy only when the publisher is used."""
    if name == "NodeStatePublisher":
        from faultledger.nodemon.publisher import NodeStatePublisher

        return NodeStatePublisher
    raise AttributeError(name)
