"""Bridges: ROS nodes that turn what the field already publishes into fault reports.

Each bridge is a module here defining ``Settings`` (a pydantic model: the documented YAML),
``NODE_NAME`` and ``Bridge(node, settings, reporter)`` with ``close()``. It reports through a
FaultReporter (no local filtering: bridges are edge-triggered already), so a bridge behaves the
same standalone (``faultledger bridge NAME --config FILE``) and inside ``faultledger serve``.
"""

from __future__ import annotations

BRIDGES: dict[str, str] = {
    "action_status": "faultledger.ros.bridges.action_status",
    "node_state": "faultledger.ros.bridges.node_state",
    "hardware_status": "faultledger.ros.bridges.hardware_status",
    "diagnostics": "faultledger.ros.bridges.diagnostics",
}
"""Bridge name (YAML key; the CLI also accepts hyphens) → module."""
